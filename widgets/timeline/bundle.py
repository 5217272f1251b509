"""The timeline's front end: the esbuild bundle ``widgets/static/timeline.js``.

The sources (``widgets/js/src/timeline.js`` and the modules it imports from
``widgets/js/src/timeline/`` and ``widgets/js/src/shared/``) are ES modules
with relative imports, which anywidget cannot resolve from a string: only the
bundle runs. It is built, not committed (``npm --prefix widgets/js run build``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

_WIDGETS = Path(__file__).resolve().parent.parent

#: the bundle anywidget loads (built by widgets/js/build.mjs)
TIMELINE_BUNDLE = _WIDGETS / "static" / "timeline.js"

_cache: dict[str, Any] = {}


def load_timeline_bundle(path: Path = TIMELINE_BUNDLE) -> str:
    """The front end's ESM text, re-read when the bundle changes on disk.

    Raises
    ------
    FileNotFoundError
        When the bundle was not built.
    """
    try:
        stat = path.stat()
    except FileNotFoundError:
        raise FileNotFoundError(
            f"the timeline's JavaScript bundle {path} is missing: it is built from "
            "widgets/js/src (esbuild). Run `npm --prefix widgets/js ci && "
            "npm --prefix widgets/js run build`."
        ) from None
    key = (str(path), stat.st_mtime_ns, stat.st_size)
    if _cache.get("key") != key:
        _cache["key"] = key
        _cache["text"] = path.read_text(encoding="utf-8")
    return str(_cache["text"])
