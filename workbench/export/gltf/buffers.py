"""The binary buffer of a glTF file and the bufferViews and accessors (dense or sparse) into it.

Written with pygltflib (objects + binary blob). Its pitfall: accessors default
to ``byteOffset=0``, which is invalid for a sparse accessor without a
bufferView, so it is set to None there.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pygltflib
from numpy.typing import NDArray

_ARRAY_BUFFER = 34962
_ELEMENT_ARRAY_BUFFER = 34963


class _Blob:
    """Accumulates the binary buffer and the bufferViews/accessors that point into it."""

    def __init__(self, gltf: pygltflib.GLTF2) -> None:
        self.gltf = gltf
        self.chunks: list[bytes] = []
        self.size = 0

    def view(self, data: bytes, target: int | None = None) -> int:
        pad = (-self.size) % 4
        if pad:
            self.chunks.append(b"\0" * pad)
            self.size += pad
        self.gltf.bufferViews.append(
            pygltflib.BufferView(buffer=0, byteOffset=self.size, byteLength=len(data), target=target)
        )
        self.chunks.append(data)
        self.size += len(data)
        return len(self.gltf.bufferViews) - 1

    def accessor(
        self,
        array: NDArray[Any],
        type_: str,
        *,
        target: int | None = None,
        minmax: bool = False,
    ) -> int:
        a = np.ascontiguousarray(array)
        ctype = {np.dtype(np.float32): pygltflib.FLOAT, np.dtype(np.uint32): pygltflib.UNSIGNED_INT}[
            a.dtype
        ]
        count = a.shape[0]
        acc = pygltflib.Accessor(
            bufferView=self.view(a.tobytes(), target),
            componentType=ctype,
            count=count,
            type=type_,
        )
        if minmax:
            flat = a.reshape(count, -1)
            acc.min = [float(x) for x in flat.min(axis=0)]
            acc.max = [float(x) for x in flat.max(axis=0)]
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1

    def sparse_vec3(self, delta: NDArray[np.float32]) -> int:
        """A VEC3 float accessor of ``len(delta)`` elements storing only the non-zero rows."""
        n = delta.shape[0]
        nz = np.flatnonzero(np.any(delta != 0, axis=1)).astype(np.uint32)
        if nz.size == 0:
            nz = np.zeros(1, np.uint32)  # sparse.count must be >= 1
        vals = np.ascontiguousarray(delta[nz], np.float32)
        # min/max over *all* elements, zeros included (validator rule)
        full_min = np.minimum(vals.min(axis=0), 0.0) if nz.size < n else vals.min(axis=0)
        full_max = np.maximum(vals.max(axis=0), 0.0) if nz.size < n else vals.max(axis=0)
        acc = pygltflib.Accessor(
            componentType=pygltflib.FLOAT,
            count=n,
            type=pygltflib.VEC3,
            min=[float(x) for x in full_min],
            max=[float(x) for x in full_max],
            sparse=pygltflib.Sparse(
                count=int(nz.size),
                indices=pygltflib.AccessorSparseIndices(
                    bufferView=self.view(nz.tobytes()), componentType=pygltflib.UNSIGNED_INT
                ),
                values=pygltflib.AccessorSparseValues(bufferView=self.view(vals.tobytes())),
            ),
        )
        acc.byteOffset = None  # pygltflib writes 0, invalid without a bufferView
        acc.sparse.indices.byteOffset = None
        acc.sparse.values.byteOffset = None
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1

    def data(self) -> bytes:
        pad = (-self.size) % 4
        return b"".join(self.chunks) + b"\0" * pad
