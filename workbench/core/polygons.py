"""Original polygon faces (quads, n-gons) kept beside the triangulation.

Artists' meshes are mostly quads; the numerical methods need triangles. We keep
the source polygons in a compact CSR-like layout so exports can write the
artist's topology back, and we triangulate by fanning each polygon from its
first corner (exact for planar convex quads, which is what face meshes have).
No kept library stores polygons with a triangle map, hence this small module.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclass(frozen=True, eq=False)
class Polygons:
    """Polygon faces in CSR layout.

    Parameters
    ----------
    indices : (s,) int
        Vertex ids of all polygons, concatenated.
    offsets : (p + 1,) int
        Polygon ``i`` is ``indices[offsets[i]:offsets[i + 1]]``; ``offsets[0] == 0``.
    """

    indices: NDArray[np.int32]
    offsets: NDArray[np.int64]

    def __post_init__(self) -> None:
        idx = np.ascontiguousarray(self.indices, dtype=np.int32).reshape(-1)
        off = np.ascontiguousarray(self.offsets, dtype=np.int64).reshape(-1)
        if off.size == 0 or off[0] != 0 or off[-1] != idx.size or np.any(np.diff(off) < 3):
            raise ValueError(
                "polygons: offsets must start at 0, end at len(indices) and give >= 3 "
                "corners per polygon"
            )
        idx.setflags(write=False)
        off.setflags(write=False)
        object.__setattr__(self, "indices", idx)
        object.__setattr__(self, "offsets", off)

    @classmethod
    def from_triangles(cls, faces: ArrayLike) -> Polygons:
        """Wrap an (m, 3) triangle array as polygons (one polygon per triangle)."""
        f = np.asarray(faces, dtype=np.int32).reshape(-1, 3)
        return cls(f.reshape(-1), np.arange(0, 3 * len(f) + 1, 3, dtype=np.int64))

    @classmethod
    def from_lists(cls, polygons: list[list[int]] | list[tuple[int, ...]]) -> Polygons:
        """Build from a Python list of corner lists."""
        sizes = np.fromiter((len(p) for p in polygons), dtype=np.int64, count=len(polygons))
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        indices = (
            np.fromiter((i for p in polygons for i in p), dtype=np.int64, count=int(offsets[-1]))
            if len(polygons)
            else np.zeros(0, np.int64)
        )
        return cls(indices.astype(np.int32), offsets)

    def __len__(self) -> int:
        return int(self.offsets.size - 1)

    @property
    def sizes(self) -> NDArray[np.int64]:
        """(p,) int: number of corners of each polygon."""
        return np.diff(self.offsets)

    def __getitem__(self, i: int) -> NDArray[np.int32]:
        return self.indices[self.offsets[i] : self.offsets[i + 1]]

    def triangulate(self) -> tuple[NDArray[np.int32], NDArray[np.int32]]:
        """Fan-triangulate every polygon from its first corner.

        Returns
        -------
        faces : (m, 3) int32
            Triangles, in polygon order; corner order (orientation) is kept.
        triangle_polygon : (m,) int32
            Index of the polygon each triangle came from.
        """
        sizes = self.sizes
        n_tri = sizes - 2
        poly_of_tri = np.repeat(np.arange(len(self), dtype=np.int32), n_tri)
        # k-th triangle of a polygon: corners (0, k+1, k+2)
        first_tri = np.concatenate([[0], np.cumsum(n_tri)[:-1]])
        k = np.arange(poly_of_tri.size) - np.repeat(first_tri, n_tri)
        base = self.offsets[:-1][poly_of_tri]
        faces = np.stack(
            [self.indices[base], self.indices[base + k + 1], self.indices[base + k + 2]], axis=1
        ).astype(np.int32)
        return faces, poly_of_tri

    def equals(self, other: Polygons) -> bool:
        return bool(
            np.array_equal(self.indices, other.indices)
            and np.array_equal(self.offsets, other.offsets)
        )
