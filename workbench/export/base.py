"""What every export writer shares: the errors, the result and atomic writing.

Writer modules (one per format: :mod:`.gltf`, :mod:`.usd`, :mod:`.pointcache`,
:mod:`.csv`, :mod:`.blender`) import this module, never the package: the
package's :func:`~workbench.export.export` finds them by module name
(:data:`~workbench.export.FORMATS`), so no writer imports back into the
dispatcher (no import cycle). Everything here is re-exported by
:mod:`workbench.export`.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "ExportError",
    "ExportResult",
    "LayerReport",
    "atomic_path",
    "atomic_write_bytes",
]


class ExportError(ValueError):
    """The model/timeline cannot be written in the requested format."""


@dataclass(frozen=True)
class LayerReport:
    """How one editing layer of the model went into an export.

    Attributes
    ----------
    name : str
        The layer's name in ``model.pipeline.names`` (``"regions"``,
        ``"handles"``, ``"paint"``, ``"wrinkles"``, ...).
    encoding : {"linear", "baked", "inactive", "omitted"}
        ``linear``: written exactly as morph targets / blend shapes;
        ``baked``: written per frame (exact at the frames);
        ``inactive``: moves nothing; ``omitted``: the format cannot hold it (CSV).
    detail : str
        A sentence for people.
    """

    name: str
    encoding: str
    detail: str


class ExportResult(list[Path]):
    """The files an export wrote (a plain list of Path) plus :attr:`layers`.

    ``layers`` is a tuple of :class:`LayerReport`, one per layer of the model.
    """

    def __init__(self, paths: list[Path] | tuple[Path, ...] = (), layers: tuple[LayerReport, ...] | list[LayerReport] = ()) -> None:
        super().__init__(paths)
        self.layers: tuple[LayerReport, ...] = tuple(layers)

    def by_encoding(self, encoding: str) -> list[str]:
        """Names of the layers with ``encoding`` (e.g. ``"baked"``)."""
        return [r.name for r in self.layers if r.encoding == encoding]


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success rename it onto ``path``.

    The temporary file is removed if the body raises, so ``path`` is either
    the old file or the complete new one. The file gets the mode of a normal
    new file, ``0o666 & ~umask`` (mkstemp creates it 0600), as
    :func:`workbench.fileformat.save_model` does; it is set again before the
    rename because some writers (USD) replace the temporary file.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=f".tmp{p.suffix}", dir=p.parent)
    os.close(fd)
    tmp_p = Path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    mode = 0o666 & ~umask
    try:
        os.chmod(tmp_p, mode)
        yield tmp_p
        os.chmod(tmp_p, mode)
        os.replace(tmp_p, p)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_p.unlink()
        raise


def atomic_write_bytes(path: str | Path, data: bytes | bytearray | memoryview) -> Path:
    """Write ``data`` to ``path`` atomically (temp file + fsync + rename)."""
    p = Path(path)
    with atomic_path(p) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    return p
