"""``.npy`` / ``.npz`` capture files, read with ``allow_pickle=False``; errors name the array."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.capture.inputs.errors import CaptureInputError


def _npz_scalar(src: str, z: Any, key: str, kind: type) -> Any:
    a = z[key]
    if a.shape not in ((), (1,)):
        raise CaptureInputError(
            src, f"expected a single value, got shape {a.shape}", field=f"array {key!r}"
        )
    v = a.reshape(())[()]
    try:
        return kind(v.item() if hasattr(v, "item") else v)
    except (TypeError, ValueError):
        raise CaptureInputError(
            src, f"expected {kind.__name__}, got {v!r}", field=f"array {key!r}"
        ) from None


def _open_npz(p: Path) -> Any:
    try:
        return np.load(p, allow_pickle=False)
    except Exception as exc:
        raise CaptureInputError(str(p), f"cannot read as .npz/.npy: {exc}", field="file") from None


def _npz_array(src: str, z: Any, key: str) -> NDArray[Any]:
    try:
        return np.asarray(z[key])
    except ValueError as exc:  # object arrays need pickle, refused
        raise CaptureInputError(src, f"cannot read: {exc}", field=f"array {key!r}") from None
