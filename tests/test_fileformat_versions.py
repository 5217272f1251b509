"""Every ``.fwb`` schema version this app can read has a file written by it, and each loads.

The detailed checks of what those files hold live beside them:
``tests/test_fileformat.py::test_schema_v1_file_still_loads`` (schema 1,
``tests/data/schema_v1_tiny.fwb``) and ``tests/test_fileformat_compat.py``
(schema 2, ``tests/data/main_v2/*.fwb``, with the vertices they evaluated to).
This test keeps the set complete: a schema bump (``SCHEMA_VERSION``) without a
migration, or without a frozen file of the version it replaces, fails here.
CHANGELOG.md lists which app version wrote which schema.
"""

from __future__ import annotations

import json
import zipfile
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench.fileformat import SCHEMA_VERSION
from workbench.fileformat.schema import _MIGRATIONS

DATA = Path(__file__).parent / "data"


def _files_by_schema() -> dict[int, list[Path]]:
    out: dict[int, list[Path]] = defaultdict(list)
    for path in sorted(DATA.rglob("*.fwb")):
        with zipfile.ZipFile(path) as zf:
            manifest = json.loads(zf.read("manifest.json"))
        out[int(manifest["schema_version"])].append(path)
    return dict(out)


def test_a_frozen_file_for_every_schema_version() -> None:
    found = _files_by_schema()
    assert sorted(found) == list(range(1, SCHEMA_VERSION + 1)), found
    # each older version is upgraded by a migration to the next one
    assert sorted(_MIGRATIONS) == list(range(1, SCHEMA_VERSION))


@pytest.mark.parametrize(
    "path", [p for files in _files_by_schema().values() for p in files],
    ids=lambda p: str(p.relative_to(DATA)),
)
def test_every_frozen_file_loads_saves_and_reloads(path: Path, tmp_path: Path) -> None:
    model = workbench.load(path)
    mesh = model.evaluate()
    assert np.isfinite(mesh).all() and mesh.shape == model.vertices.shape
    # saved by today's code it is the current schema and evaluates the same
    out = tmp_path / path.name
    model.save(out)
    with zipfile.ZipFile(out) as zf:
        assert json.loads(zf.read("manifest.json"))["schema_version"] == SCHEMA_VERSION
    np.testing.assert_array_equal(workbench.load(out).evaluate(), mesh)
