"""The timeline's front end: the esbuild bundle ``widgets/static/timeline.js``.

The sources (``widgets/js/src/timeline.js`` and the modules it imports from
``widgets/js/src/timeline/`` and ``widgets/js/src/shared/``) are ES modules
with relative imports, which anywidget cannot resolve from a string: only the
bundle runs. It is built, not committed (``npm --prefix widgets/js run build``).
"""

from __future__ import annotations

from pathlib import Path

from widgets.viewport.common import read_bundle

_WIDGETS = Path(__file__).resolve().parent.parent

#: the bundle anywidget loads (built by widgets/js/build.mjs)
TIMELINE_BUNDLE = _WIDGETS / "static" / "timeline.js"

def load_timeline_bundle(path: Path = TIMELINE_BUNDLE) -> str:
    """The front end's ESM text, re-read when the bundle changes on disk.

    Raises
    ------
    FileNotFoundError
        When the bundle was not built.
    """
    return read_bundle(
        path,
        f"the timeline's JavaScript bundle {path} is missing: it is built from "
        "widgets/js/src (esbuild). Run `npm --prefix widgets/js ci && "
        "npm --prefix widgets/js run build`.",
    )
