"""The package version, in a leaf module so that anything may import it.

``__version__`` is the installed distribution's version (``face-workbench`` in
the package metadata, which ``pyproject.toml`` sets), so a wheel, an sdist and an
editable install all report what pip installed. A source checkout that was never
installed reads ``pyproject.toml`` beside the package instead.
"""

from __future__ import annotations

from importlib import metadata
from pathlib import Path

DISTRIBUTION = "face-workbench"


def _source_version() -> str:
    """The version ``pyproject.toml`` states, for a checkout that is not installed."""
    import tomllib

    pyproject = Path(__file__).resolve().parent.parent / "pyproject.toml"
    try:
        with pyproject.open("rb") as f:
            return str(tomllib.load(f)["project"]["version"])
    except (OSError, KeyError, tomllib.TOMLDecodeError):
        return "0+unknown"


try:
    __version__: str = metadata.version(DISTRIBUTION)
except metadata.PackageNotFoundError:
    __version__ = _source_version()
