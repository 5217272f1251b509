"""Spatial performance enhancement (Bermano et al. 2014, §5): detail from the database onto input frames.

Per input frame ``a`` (any resolution, through a :class:`Correspondence`):

1. **Correspondence** (§5.1): ``ā = offset + C a`` on the database's mesh — the
   Loop subdivision operator when the database is a subdivision of the input
   (the sample head's 25k → 80k → 318k), the identity for the same mesh, or a
   barycentric map onto the input neutral's surface (displacements carried,
   the database neutral's shape kept) for any other mesh in the same place and
   units (bring a differently shaped face there with :mod:`workbench.rigging` first).
2. **Frequency separation**: ``f(ā)`` by the database's own filter (eq. 1, factored once).
3. **Encoding + matching** (§5.2–5.3): ``f(ā)`` Horn-aligned to ``f(d0)``, its
   compressed shape-space vector projected onto the database per voluntary
   region with convex weights (eq. 2–3, the region normal matrices precomputed).
4. **Interpolation** (§5.4, eq. 4): the database's high-frequency detail
   gradients blended by the region weights and composed with the low-frequency
   gradients of ``f(ā)``.
5. **Reconstruction** (§5.5): one back-substitution of the Poisson system
   factored on ``f(d0)``. The pose needs no restoring: detail is stored in each
   low-frequency triangle's own frame, so the composition happens in the input's pose.
   Each connected piece is then placed so that the result's own low band has the
   input's centroid (``mean f(x) = mean f(ā)``: the filter keeps translations, so
   this is one more back-substitution) — the curvature flow moves centroids of
   curved pieces, and the input's centroid is not the detailed one.

Hand-written glue over :class:`~workbench.enhance.database.PerformanceDatabase`
(no library implements the paper); the solves are CHOLMOD's.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from workbench.blas import one_blas_thread
from workbench.enhance.errors import DatabaseError

if TYPE_CHECKING:
    from workbench.enhance.database import PerformanceDatabase

__all__ = ["Correspondence", "EnhanceResult", "enhance_frames"]

Progress = Callable[[float, str], Any]


@dataclass(frozen=True)
class Correspondence:
    """A linear map from input frames (n_in, 3) to the database mesh: ``offset + matrix @ a``.

    Attributes
    ----------
    matrix : (n, n_in) scipy.sparse CSR
    offset : (n, 3) float64 or None
    restriction : (n_in, n) scipy.sparse CSR or None
        Back from the database mesh to the input mesh (what the *Enhanced* preview
        shows on the model): the input vertices' own rows for a subdivision, the
        closest points for a surface map; None when not known.
    kind : str
        ``"identity"``, ``"loop"`` or ``"surface"`` (or ``"custom"``).
    """

    matrix: sp.csr_matrix
    offset: NDArray[np.float64] | None = None
    restriction: sp.csr_matrix | None = None
    kind: str = "custom"

    @property
    def n_in(self) -> int:
        return int(self.matrix.shape[1])

    @property
    def n_out(self) -> int:
        return int(self.matrix.shape[0])

    def __call__(self, frames: NDArray[np.float64]) -> NDArray[np.float64]:
        """Map (T, n_in, 3) frames to (T, n, 3)."""
        T = frames.shape[0]
        flat = frames.transpose(1, 0, 2).reshape(self.n_in, 3 * T)
        out = np.asarray(self.matrix @ flat).reshape(self.n_out, T, 3).transpose(1, 0, 2)
        return out + self.offset if self.offset is not None else np.ascontiguousarray(out)

    def restrict(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """Per-vertex values (n, d) on the database mesh back onto the input mesh, (n_in, d)."""
        if self.restriction is None:
            raise ValueError(f"this {self.kind} correspondence has no map back to the input mesh")
        return np.asarray(self.restriction @ values)

    @classmethod
    def identity(cls, n: int) -> Correspondence:
        """The input is the database's own mesh."""
        eye = sp.identity(int(n), format="csr", dtype=np.float64)
        return cls(eye, restriction=eye, kind="identity")

    @classmethod
    def loop(cls, faces: ArrayLike, n_vertices: int, levels: int = 1) -> Correspondence:
        """The database mesh is ``levels`` Loop subdivisions of the input mesh (``faces``, ``n_vertices``).

        This is how the sample head's resolutions are made (:func:`workbench.load_sample`):
        ``25k`` → ``100k`` is one level, ``25k`` → ``300k`` two. The first ``n_vertices``
        rows of a subdivided mesh belong to the input's vertices (moved by the
        subdivision's smoothing, so the restriction carries displacements, which is
        how the preview layer uses it, not positions).
        """
        from workbench.geometry.subdivision import loop_subdivision

        n_in = int(n_vertices)
        S, _ = loop_subdivision(faces, n_in, int(levels))
        back = sp.csr_matrix((np.ones(n_in), (np.arange(n_in), np.arange(n_in))), shape=(n_in, S.shape[0]))
        return cls(sp.csr_matrix(S), restriction=back, kind="loop")

    @classmethod
    def from_surface(
        cls,
        input_neutral: ArrayLike,
        input_faces: ArrayLike,
        database_neutral: ArrayLike,
        database_faces: ArrayLike | None = None,
    ) -> Correspondence:
        """Barycentric map from each database vertex to the closest point of the input neutral's surface.

        The input's *displacements* are carried (``ā = d0 + B (a − a0)``), so the
        database neutral keeps its own shape. Both meshes must be in the same place,
        units and axes (after :mod:`workbench.rigging` for a different face). With
        ``database_faces`` the map back (input vertices onto the database surface) is built too.
        """
        from workbench.geometry.surface import SurfaceQuery

        a0 = np.asarray(input_neutral, np.float64)
        d0 = np.asarray(database_neutral, np.float64)
        B = _barycentric_map(SurfaceQuery(a0, np.asarray(input_faces, np.int64)), d0, len(a0))
        back = None
        if database_faces is not None:
            back = _barycentric_map(SurfaceQuery(d0, np.asarray(database_faces, np.int64)), a0, len(d0))
        return cls(B, d0 - np.asarray(B @ a0), back, "surface")


def _barycentric_map(query: Any, points: NDArray[np.float64], n_source: int) -> sp.csr_matrix:
    """(p, n_source) rows of barycentric weights of each point's closest point on ``query``'s surface."""
    _, face, _, bary = query.closest(points)
    rows = np.repeat(np.arange(len(points)), 3)
    return sp.csr_matrix((bary.ravel(), (rows, query.F[face].ravel())), shape=(len(points), n_source))


@dataclass
class EnhanceResult:
    """Enhanced frames and what the matching chose.

    Attributes
    ----------
    frames : (T, n, 3) float64
        Enhanced frames on the database's mesh.
    weights : (T, R, D) float64
        Convex database weights per frame and voluntary region (eq. 3).
    inputs : (T, n, 3) float64
        The input frames on the database's mesh (``ā``), what enhancement started from.
    seconds : dict
        Time spent per stage (summed over frames).
    """

    frames: NDArray[np.float64]
    weights: NDArray[np.float64]
    inputs: NDArray[np.float64]
    seconds: dict[str, float] = field(default_factory=dict)


def check_input_frames(frames: ArrayLike, n_in: int, what: str = "frames") -> NDArray[np.float64]:
    """(T, n_in, 3) float64 frames, or a clear ``DatabaseError``."""
    x = np.asarray(frames, dtype=np.float64)
    if x.ndim == 2:
        x = x[None]
    if x.ndim != 3 or x.shape[2] != 3:
        raise DatabaseError(f"{what} must be (T, n, 3) or (n, 3), got shape {np.shape(frames)}")
    if x.shape[0] == 0:
        raise DatabaseError(f"{what} is empty: nothing to enhance")
    if x.shape[1] != n_in:
        raise DatabaseError(
            f"{what} have {x.shape[1]} vertices but the correspondence expects {n_in}: pass "
            "correspondence=Correspondence.loop(...) or .from_surface(...) for a mesh that is not the database's"
        )
    bad = ~np.isfinite(x).all(axis=(1, 2))
    if bad.any():
        raise DatabaseError(f"{what} contains NaN/inf (frame {int(np.flatnonzero(bad)[0])} of {x.shape[0]})")
    return x


def enhance_frames(
    db: PerformanceDatabase,
    frames: ArrayLike,
    *,
    correspondence: Correspondence | None = None,
    progress: Progress | None = None,
) -> EnhanceResult:
    """Enhance input frames with the database's detail (see the module docstring).

    Parameters
    ----------
    db : PerformanceDatabase
    frames : (T, n_in, 3) or (n_in, 3) float
        Input animation frames (a rig, a capture, a smooth performance).
    correspondence : Correspondence, optional
        Input mesh → database mesh; default the identity (``n_in`` = the database's ``n``).
    progress : callable(fraction, message), optional

    Returns
    -------
    EnhanceResult

    Raises
    ------
    DatabaseError
        Frames of the wrong shape or vertex count, NaN/inf, a correspondence that does
        not land on the database's mesh.
    """
    n = db.neutral_.shape[0]
    corr = correspondence if correspondence is not None else Correspondence.identity(n)
    if corr.n_out != n:
        raise DatabaseError(f"correspondence maps onto {corr.n_out} vertices but the database mesh has {n}")
    x = check_input_frames(frames, corr.n_in)
    say = progress or (lambda f, msg: None)
    T = x.shape[0]
    secs = dict.fromkeys(("correspondence", "filter", "match", "blend", "reconstruct"), 0.0)
    t0 = time.perf_counter()
    inputs = corr(x)
    secs["correspondence"] = time.perf_counter() - t0
    out = np.empty_like(inputs)
    weights = np.empty((T, len(db.region_names_), db.n_frames_))
    with one_blas_thread():  # the D×D matching and 3×3 work gain nothing from threads
        _enhance_each(db, inputs, out, weights, secs, say)
    say(1.0, f"enhanced {T} frames")
    return EnhanceResult(out, weights, inputs, secs)


def _enhance_each(db: PerformanceDatabase, inputs: NDArray[np.float64], out: NDArray[np.float64],
                  weights: NDArray[np.float64], secs: dict[str, float], say: Progress) -> None:
    T = inputs.shape[0]
    for i in range(T):
        if i % 4 == 0:
            say(i / T, f"enhancing frame {i + 1} of {T}")
        t0 = time.perf_counter()
        low = db.lowpass(inputs[i])
        t1 = time.perf_counter()
        weights[i] = db.match(low)
        t2 = time.perf_counter()
        J = db.blend_compose(weights[i], low)
        t3 = time.perf_counter()
        X = db.reconstruct(J, low)
        X += db.place_pieces(X, low)
        t4 = time.perf_counter()
        out[i] = X
        secs["filter"] += t1 - t0
        secs["match"] += t2 - t1
        secs["blend"] += t3 - t2
        secs["reconstruct"] += t4 - t3
