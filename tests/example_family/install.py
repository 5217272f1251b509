"""Install the worked example's family folder as a user would: a package that declares its family.

``install(tmp_path)`` copies ``mouth_gain/`` into ``tmp_path/site`` with a
``.dist-info`` naming it in the ``face_workbench.families`` entry-point group
(what ``pip install`` of a package with that ``pyproject.toml`` table writes),
and returns the environment for a Python that has it on its path.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

HERE = Path(__file__).resolve().parent


def install(tmp_path: Path) -> dict[str, str]:
    site = tmp_path / "site"
    shutil.copytree(HERE / "mouth_gain", site / "mouth_gain", ignore=shutil.ignore_patterns("__pycache__"))
    info = site / "mouth_gain-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: mouth-gain\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[face_workbench.families]\nmouth_gain = mouth_gain.family\n")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(site), env.get("PYTHONPATH", "")) if p)
    return env
