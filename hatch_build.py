"""Hatch build hook: the wheel and the sdist always carry the built front-end bundle.

The three.js viewport and the timeline are ES modules bundled by esbuild from
``widgets/js/src/<entry>.js`` into ``widgets/static/<entry>.js`` (one file per
top-level entry). The bundles are built, not committed (``.gitignore``), so a
``python -m build`` from a fresh clone would otherwise make a wheel whose
widgets cannot draw. Before a wheel or sdist is built this hook checks that
every entry has its bundle and that no front-end source is newer than it; if
not, it runs ``npm ci`` (only when ``node_modules`` is missing or older than
``package-lock.json``) and ``npm run build`` in ``widgets/js``. Without npm and
without an up-to-date bundle the build fails with a message saying so — it
never makes a wheel without its front end.

A wheel built from the sdist finds the bundle there (the sdist carries it, with
the sources, all at one reproducible time stamp), so it needs no node at all.
Editable installs (``pip install -e``) are skipped: they use the source tree's
``widgets/static/``, which ``bash .ci/workbench`` builds.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path
from typing import Any

from hatchling.builders.hooks.plugin.interface import BuildHookInterface


def _entries(js: Path) -> list[str]:
    """Names of the bundle entry points (``src/*.js`` directly under ``src``)."""
    return sorted(p.stem for p in (js / "src").glob("*.js"))


def _sources(js: Path) -> list[Path]:
    names = ["build.mjs", "package.json", "package-lock.json"]
    return [js / n for n in names if (js / n).is_file()] + sorted((js / "src").rglob("*.js"))


def stale_bundles(root: Path) -> list[str]:
    """Bundles that are missing or older than a front-end source (empty: up to date).

    Parameters
    ----------
    root : Path
        The repository (or unpacked sdist) root.

    Returns
    -------
    list of str
        Paths of the bundles to rebuild, relative to ``root``.
    """
    js = root / "widgets" / "js"
    static = root / "widgets" / "static"
    if not (js / "src").is_dir():
        return []  # no sources to build from: the hook's final check wants the bundles present
    newest = max(p.stat().st_mtime for p in _sources(js))
    out = []
    for name in _entries(js):
        b = static / f"{name}.js"
        if not b.is_file() or b.stat().st_mtime < newest:
            out.append(str(b.relative_to(root)))
    return out


def build_frontend(root: Path) -> None:
    """Run ``npm ci`` (when needed) and ``npm run build`` in ``widgets/js``.

    Parameters
    ----------
    root : Path
        The repository root.

    Raises
    ------
    RuntimeError
        When npm is not on ``PATH`` or the build fails.
    """
    js = root / "widgets" / "js"
    npm = shutil.which("npm")
    if npm is None:
        raise RuntimeError(
            "face-workbench: the front-end bundle (widgets/static/*.js) is missing or older than "
            "widgets/js/src, and npm is not on PATH to build it. Install node/npm (Debian: "
            "apt-get install nodejs npm) or run `npm --prefix widgets/js ci && npm --prefix "
            "widgets/js run build` first."
        )
    modules = js / "node_modules" / ".package-lock.json"
    lock = js / "package-lock.json"
    if not modules.is_file() or lock.stat().st_mtime > modules.stat().st_mtime:
        subprocess.run(
            [npm, "ci", "--prefix", str(js), "--no-audit", "--no-fund", "--loglevel=error"],
            check=True,
        )
    subprocess.run([npm, "--prefix", str(js), "run", "--silent", "build"], check=True)


class FrontendBuildHook(BuildHookInterface):  # type: ignore[type-arg]
    """Build (if needed) and check the front-end bundle before a wheel or sdist."""

    PLUGIN_NAME = "custom"

    def initialize(self, version: str, build_data: dict[str, Any]) -> None:
        """Make sure ``widgets/static/*.js`` exists and is up to date (hatch calls this).

        Parameters
        ----------
        version : str
            ``"standard"`` for a wheel or sdist, ``"editable"`` for ``pip install -e``.
        build_data : dict
            Hatch's build data (unchanged).
        """
        if version == "editable":
            return
        root = Path(self.root)
        stale = stale_bundles(root)
        if stale:
            self.app.display_info(f"building the front-end bundle ({', '.join(stale)})")
            build_frontend(root)
            stale = stale_bundles(root)
            if stale:
                raise RuntimeError(f"face-workbench: npm run build did not write {stale}")
        missing = [n for n in ("viewport.js", "timeline.js", "camera.js")
                   if not (root / "widgets" / "static" / n).is_file()]
        if missing:
            raise RuntimeError(f"face-workbench: widgets/static/ lacks {missing}")
