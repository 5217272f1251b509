"""Handle-driven linear thin-shell deformation (Bickel et al. 2008, §4).

The large-scale displacement ``u`` of a face minimizes a quadratic thin-shell
energy whose Euler–Lagrange equations are

    -k_s Δu + k_b Δ²u = 0

under the displacements ``u_H`` prescribed at ``H`` handle vertices. With the
cotangent Laplacian ``L`` (negative semi-definite, :mod:`workbench.geometry.operators`)
and the Voronoi mass ``M`` this is ``A u = 0`` with

    A = -k_s L + k_b L^T M̃^{-1} L,      M̃ = M · N_REF / area

where ``area = trace M`` is the total area of the triangles being solved and
``N_REF`` (:data:`REFERENCE_VERTEX_COUNT`) is a fixed number. ``L`` and
``M^{-1} L`` converge under refinement, so this discretizes the *continuum* energy

    E(u) = k_s ∫ |∇u|² dA + k_b (area / N_REF) ∫ (Δu)² dA

**Meaning of k_s and k_b.** Both are dimensionless, and only their ratio shapes
the result (``u`` depends on ``A`` up to a factor). The bending weight is
measured in units of ``area / N_REF``, so the length over which bending
dominates stretching is ``ℓ = sqrt(k_b / k_s · area / N_REF)``: with the
defaults (``k_b / k_s = 10``) ``ℓ ≈ 0.048 · sqrt(area)`` ≈ 2 cm on the sample
head's skin. What is held fixed is ``ℓ`` relative to the size of the surface,
so the same ``k_s``, ``k_b`` and drag give the same shape

* at any resolution (refining the mesh changes neither ``area`` nor the
  continuum energy; the handle displacement field converges), and
* at any scale or in any units (scaling the mesh and the handle displacements
  by ``s`` scales ``u`` by ``s``: ``L`` is scale-invariant and ``M̃`` is too).

``N_REF = 4328`` is the skin vertex count of the base sample head, so there
``M̃ = M / mean(diag M)`` (the normalization used before, which made the
bending weight shrink like ``1 / n`` on finer meshes) and its look is
unchanged. Splitting the vertices into free ``f`` and
handle ``H`` ones, ``A_ff u_f = -A_fH u_H``. We factor ``A_ff`` once (CHOLMOD
when installed, see :mod:`workbench.geometry.sparse_cholesky`), solve all ``H`` columns
and keep the basis ``B = -A_ff^{-1} A_fH`` in float32, so a drag is
``u = B u_H`` — and moving one handle is a rank-1 update ``u += B[:, j] d^T``.

Set-up rules (documented choices, each pinned by a test):

* **Open boundaries** (the neck cut) of the components being solved are
  pinned (``u = 0``) by default (``pin_boundary=True``), so the head does not
  float away when a handle moves; a handle on the boundary wins over the pin.
* **Components without a handle** (eyes, teeth, tongue, lashes) are not part of
  the solve — they would make ``A_ff`` singular. Each follows a policy:
  ``"fixed"`` (stays put: eyeballs, upper teeth — attached to the skull),
  ``"follow"`` (each vertex copies the displacement of its nearest solved
  vertex: eyelashes ride on the lids), ``"rigid"`` (the component translates
  with the mean displacement of the 16 solved vertices nearest to it: lower
  teeth and tongue go with the chin/lips). The default comes from the
  component's *role* (:func:`workbench.geometry.parts.component_roles`: from
  its name, else recognised by geometry, so an unnamed eyeball is still an
  eyeball) through :data:`DEFAULT_ROLE_POLICY`; ``component_policy`` patterns
  on the component *name* override it. Unrecognised parts are ``"rigid"``.
* **Duplicate handles** (the same vertex listed twice) share one basis
  column; :meth:`ShellDeformer.deform` uses the mean of their target positions.
* **Coincident handles** (*distinct* vertices at one position, e.g. the two
  copies of a seam-split vertex) are independent handles: one basis column
  each, each interpolated exactly, never averaged. Give them equal
  displacements to keep the seam closed there (the solve sees only the mesh's
  connectivity, so the two sides of a cut deform as separate sheets).
"""

from __future__ import annotations

import fnmatch
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Literal

import igl
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from workbench.geometry.operators import bilaplacian, cotangent_laplacian, mass_matrix
from workbench.geometry.parts import component_roles
from workbench.geometry.sparse_cholesky import Backend, SparseSPDSolver

Policy = Literal["fixed", "follow", "rigid"]

#: part role (:data:`workbench.geometry.parts.ROLES`) -> policy for components that hold no handle
DEFAULT_ROLE_POLICY: dict[str, Policy] = {
    "eyeball_left": "fixed",
    "eyeball_right": "fixed",
    "eyeball": "fixed",
    "teeth_upper": "fixed",
    "teeth_lower": "rigid",
    "teeth": "rigid",
    "tongue": "rigid",
    "lashes": "follow",
    "brows": "follow",
    "hair": "follow",
    "skin": "rigid",
    "other": "rigid",
}

#: defaults that give smooth, skin-like results on the sample head (bending dominated,
#: a little stretching so the influence of a handle decays within a few centimetres)
DEFAULT_K_S = 1.0
DEFAULT_K_B = 10.0
#: ``N_REF``: the mass is scaled by ``N_REF / area`` (see the module docstring); the
#: skin vertex count of the base sample head, so its results match the old
#: ``M / mean(diag M)`` normalization
REFERENCE_VERTEX_COUNT = 4328
_RIGID_NEIGHBOURS = 16


def _policy_for(name: str, role: str, overrides: Mapping[str, Policy]) -> Policy:
    for pattern, policy in overrides.items():
        if fnmatch.fnmatchcase(name, pattern):
            return policy
    return DEFAULT_ROLE_POLICY.get(role, "rigid")


def shell_system_matrix(
    V: ArrayLike, F: ArrayLike, k_s: float = DEFAULT_K_S, k_b: float = DEFAULT_K_B
) -> sp.csr_matrix:
    """``A = -k_s L + k_b L^T M̃^{-1} L`` (symmetric positive semi-definite).

    ``M̃ = M · N_REF / area`` with ``area`` the total area of ``F`` and ``N_REF =``
    :data:`REFERENCE_VERTEX_COUNT`, so the energy ``u^T A u`` discretizes
    ``k_s ∫|∇u|² + k_b (area / N_REF) ∫(Δu)²`` independently of resolution and units.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
    k_s, k_b : float
        Stretching and bending stiffness (>= 0, not both 0; dimensionless, see
        the module docstring).
    """
    if k_s < 0 or k_b < 0 or (k_s == 0 and k_b == 0):
        raise ValueError(f"need k_s >= 0, k_b >= 0, not both zero; got k_s={k_s}, k_b={k_b}")
    L = cotangent_laplacian(V, F)
    M = mass_matrix(V, F)
    area = float(M.diagonal().sum())
    # M̃ = M / scale: scale = area / N_REF is the mean vertex area of an N_REF-vertex mesh
    scale = area / REFERENCE_VERTEX_COUNT if area > 0 else 1.0
    A = sp.csr_matrix(L.shape)
    if k_s:
        A = A - k_s * L
    if k_b:
        A = A + k_b * bilaplacian(L, M / scale)
    return sp.csr_matrix(A)


class ShellDeformer:
    """Precomputed linear-shell basis for one mesh and one handle set.

    Parameters
    ----------
    vertices : (n, 3) float
        Rest pose.
    faces : (m, 3) int
    handles : (H,) int
        Handle vertex ids, in the order :meth:`deform` expects their positions.
        A vertex listed twice is one handle (its targets are averaged);
        distinct vertices at the same position (seam copies) are separate
        handles, each meeting its own target exactly, so pass them equal
        displacements to keep the seam closed.
    k_s, k_b : float
        Stretching and bending stiffness (dimensionless; see module docstring).
    pin_boundary : bool
        Keep the open boundary of solved components in place.
    fixed : (p,) int, optional
        More vertices to keep in place.
    component_labels : (n,) int, optional
        Connected component of each vertex (default: computed from ``faces``).
    component_names : sequence of str, optional
        Names for the labels.
    component_roles : sequence of str, optional
        Role of every component (:func:`workbench.geometry.parts.component_roles`;
        computed from the mesh and names when not given); picks the policy of
        handle-less components through :data:`DEFAULT_ROLE_POLICY`.
    component_policy : mapping, optional
        ``{"name pattern": "fixed" | "follow" | "rigid"}`` overriding the defaults.
    backend : {"auto", "cholmod", "superlu"}
        Sparse factorization used for the precompute.
    progress : callable, optional
        ``progress(fraction, message)`` called during the precompute.

    Attributes
    ----------
    basis_ : (n, H_unique) float32, Fortran order
        ``u = basis_ @ u_H``; columns follow :attr:`unique_handles_`.
    unique_handles_ : (H_unique,) int
    backend_ : str
    timings_ : dict
        Seconds spent assembling, factoring and solving.
    """

    def __init__(
        self,
        vertices: ArrayLike,
        faces: ArrayLike,
        handles: ArrayLike,
        k_s: float = DEFAULT_K_S,
        k_b: float = DEFAULT_K_B,
        *,
        pin_boundary: bool = True,
        fixed: ArrayLike | None = None,
        component_labels: ArrayLike | None = None,
        component_names: Sequence[str] | None = None,
        component_roles: Sequence[str] | None = None,
        component_policy: Mapping[str, Policy] | None = None,
        backend: Backend = "auto",
        progress: Callable[[float, str], None] | None = None,
    ) -> None:
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.handles = np.asarray(handles, dtype=np.int64).reshape(-1)
        self.k_s = float(k_s)
        self.k_b = float(k_b)
        self.pin_boundary = pin_boundary
        self.fixed = None if fixed is None else np.asarray(fixed, dtype=np.int64).reshape(-1)
        self.component_labels = component_labels
        self.component_names = component_names
        self.component_roles = component_roles
        self.component_policy = dict(component_policy or {})
        self.backend = backend
        self._progress = progress or (lambda f, m: None)
        self._validate()
        self._precompute()

    # ---------------------------------------------------------------- set-up
    def _validate(self) -> None:
        n = self.vertices.shape[0]
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise ValueError(f"vertices must be (n, 3), got {self.vertices.shape}")
        if self.handles.size == 0:
            raise ValueError("handles: need at least one handle vertex")
        if self.handles.min() < 0 or self.handles.max() >= n:
            raise ValueError(f"handles: vertex ids must be in 0..{n - 1}")
        if self.fixed is not None and self.fixed.size and (self.fixed.min() < 0 or self.fixed.max() >= n):
            raise ValueError(f"fixed: vertex ids must be in 0..{n - 1}")

    def _labels(self) -> tuple[NDArray[np.int64], list[str]]:
        n = self.vertices.shape[0]
        if self.component_labels is not None:
            labels = np.asarray(self.component_labels, dtype=np.int64).reshape(-1)
            if labels.shape[0] != n:
                raise ValueError(f"component_labels: expected {n} entries, got {labels.shape[0]}")
        else:
            adj = igl.adjacency_matrix(self.faces)
            adj = adj + sp.identity(n, format="csr")  # isolated vertices form their own component
            _, labels = sp.csgraph.connected_components(adj, directed=False)
            labels = labels.astype(np.int64)
        k = int(labels.max()) + 1
        names = list(self.component_names) if self.component_names is not None else []
        names += [f"component_{i}" for i in range(len(names), k)]
        return labels, names

    def _roles(self, labels: NDArray[np.int64], names: list[str]) -> list[str]:
        if self.component_roles is not None:
            roles = list(self.component_roles)
            if len(roles) < len(names):
                raise ValueError(f"component_roles: expected {len(names)} roles, got {len(roles)}")
            return roles
        return component_roles(self.vertices, self.faces, labels, names)

    def _precompute(self) -> None:
        t0 = time.perf_counter()
        n = self.vertices.shape[0]
        self.unique_handles_, self._handle_column = np.unique(self.handles, return_inverse=True)
        labels, names = self._labels()
        active_components = np.unique(labels[self.unique_handles_])
        active = np.isin(labels, active_components)
        # Solve only on faces of components that hold a handle.
        face_active = active[self.faces[:, 0]]
        F = self.faces[face_active]
        self._progress(0.05, "assembling operators")
        A = shell_system_matrix(self.vertices, F, self.k_s, self.k_b)
        constrained = np.zeros(n, bool)
        constrained[self.unique_handles_] = True
        pinned = np.zeros(n, bool)
        if self.pin_boundary and len(F):
            for loop in igl.boundary_loop_all(F):
                pinned[np.asarray(loop, dtype=np.int64)] = True
        if self.fixed is not None:
            pinned[self.fixed] = True
        pinned &= ~constrained
        free = active & ~constrained & ~pinned
        # vertices of active components used by no active face carry no energy
        used = np.zeros(n, bool)
        used[F.ravel()] = True
        free &= used
        free_ids = np.flatnonzero(free)
        t1 = time.perf_counter()
        self._progress(0.15, f"factoring {free_ids.size} x {free_ids.size} system")
        A = A.tocsr()
        A_ff = A[free_ids][:, free_ids].tocsc()
        A_fH = A[free_ids][:, self.unique_handles_]
        H = self.unique_handles_.size
        B = np.zeros((n, H), dtype=np.float32, order="F")
        t2 = t1
        if free_ids.size == 0:  # every vertex is a handle or pinned: nothing to solve
            self.backend_ = "none"
        else:
            solver = SparseSPDSolver(A_ff, self.backend)
            self.backend_ = solver.backend_
            t2 = time.perf_counter()
            block = 32  # bounded memory for the dense right-hand sides
            for start in range(0, H, block):
                stop = min(H, start + block)
                B[free_ids, start:stop] = solver.solve(-A_fH[:, start:stop].toarray())
                self._progress(0.2 + 0.7 * stop / H, f"solving handle columns {stop}/{H}")
        B[self.unique_handles_, np.arange(H)] = 1.0
        t3 = time.perf_counter()
        self._attach_passive_components(B, labels, names, active, free | constrained)
        self.basis_ = B
        self.timings_ = {
            "assemble": t1 - t0,
            "factor": t2 - t1,
            "solve": t3 - t2,
            "total": time.perf_counter() - t0,
        }
        self._handle_rest = self.vertices[self.handles]
        self._d_all = np.zeros((self.handles.size, 3), np.float64)
        self._u_H = np.zeros((H, 3), np.float64)
        self._u = np.zeros((n, 3), np.float32)
        self._progress(1.0, "done")

    def _attach_passive_components(
        self,
        B: NDArray[np.float32],
        labels: NDArray[np.int64],
        names: list[str],
        active: NDArray[np.bool_],
        solved: NDArray[np.bool_],
    ) -> None:
        solved_ids = np.flatnonzero(solved)
        if solved_ids.size == 0:
            return
        tree = cKDTree(self.vertices[solved_ids])
        self.policies_: dict[str, Policy] = {}
        passive = np.unique(labels[~active])
        roles = self._roles(labels, names) if passive.size else []
        for c in passive:
            ids = np.flatnonzero(labels == c)
            name = names[c] if c < len(names) else f"component_{c}"
            policy = _policy_for(name, roles[c], self.component_policy)
            self.policies_[name] = policy
            if policy == "fixed":
                continue
            if policy == "follow":
                _, nearest = tree.query(self.vertices[ids])
                B[ids] = B[solved_ids[nearest]]
            elif policy == "rigid":
                k = min(_RIGID_NEIGHBOURS, solved_ids.size)
                # the solved vertices nearest to the component as a whole
                dist, nearest = tree.query(self.vertices[ids], k=k)
                nearest = np.asarray(nearest).reshape(len(ids), -1)
                dist = np.asarray(dist).reshape(len(ids), -1)
                order = np.argsort(dist.ravel())
                chosen: list[int] = []
                for idx in nearest.ravel()[order]:
                    if idx not in chosen:
                        chosen.append(int(idx))
                    if len(chosen) == k:
                        break
                B[ids] = B[solved_ids[chosen]].mean(axis=0)
            else:
                raise ValueError(f"component_policy for {name!r}: unknown policy {policy!r}")

    # ------------------------------------------------------------- evaluate
    def _unique_displacements(self, handle_displacements: NDArray[np.float64]) -> NDArray[np.float64]:
        d = np.asarray(handle_displacements, dtype=np.float64).reshape(-1, 3)
        if d.shape[0] != self.handles.size:
            raise ValueError(
                f"expected {self.handles.size} handle positions (one per handle, in handle order), "
                f"got {d.shape[0]}"
            )
        H = self.unique_handles_.size
        if H == self.handles.size:
            out = np.empty((H, 3))
            out[self._handle_column] = d
            return out
        sums = np.zeros((H, 3))
        np.add.at(sums, self._handle_column, d)
        counts = np.bincount(self._handle_column, minlength=H)[:, None]
        return sums / counts

    def displacement(self, handle_displacements: ArrayLike) -> NDArray[np.float32]:
        """(n, 3) float32 displacement ``u = B u_H`` for (H, 3) handle displacements."""
        uH = self._unique_displacements(np.asarray(handle_displacements))
        return (self.basis_ @ uH.astype(np.float32)).astype(np.float32, copy=False)

    def deform(self, handle_positions: ArrayLike) -> NDArray[np.float32]:
        """Absolute deformed positions, (n, 3) float32.

        Parameters
        ----------
        handle_positions : (H, 3) float
            Target positions of the handle vertices, in handle order.
        """
        P = np.asarray(handle_positions, dtype=np.float64).reshape(-1, 3)
        if P.shape[0] != self.handles.size:
            raise ValueError(
                f"expected {self.handles.size} handle positions (one per handle, in handle order), "
                f"got {P.shape[0]}"
            )
        return (self.vertices + self.displacement(P - self._handle_rest)).astype(np.float32)

    # ------------------------------------------------- incremental (dragging)
    def reset(self, handle_displacements: ArrayLike | None = None) -> NDArray[np.float32]:
        """Set the current handle displacements (full product); returns the displacement."""
        if handle_displacements is None:
            handle_displacements = np.zeros((self.handles.size, 3))
        self._d_all = np.array(handle_displacements, dtype=np.float64).reshape(-1, 3)
        self._u_H = self._unique_displacements(self._d_all)
        self._u = np.ascontiguousarray(self.basis_ @ self._u_H.astype(np.float32), np.float32)
        return self._u

    def update(self, handle_index: int, displacement: ArrayLike) -> NDArray[np.float32]:
        """Move one handle: rank-1 update ``u += B[:, j] (d_new - d_old)^T``.

        Parameters
        ----------
        handle_index : int
            Index into ``handles`` (handle order).
        displacement : (3,) float
            New displacement of that handle from its rest position.

        Returns
        -------
        (n, 3) float32
            The current displacement (a view; copy before keeping it).
        """
        self._d_all[handle_index] = np.asarray(displacement, dtype=np.float64).reshape(3)
        j = int(self._handle_column[handle_index])
        d = self._d_all[self._handle_column == j].mean(axis=0)
        delta = d - self._u_H[j]
        self._u_H[j] = d
        col = self.basis_[:, j]
        for c in range(3):
            if delta[c] != 0.0:
                self._u[:, c] += np.float32(delta[c]) * col
        return self._u

    @property
    def handle_columns(self) -> NDArray[np.int64]:
        """(H,) int: the basis column of each handle (handles on one vertex share a column).

        ``displacement(d) == basis_ @ u`` where ``u[j]`` is the mean of ``d`` over the
        handles in column ``j``.
        """
        out: NDArray[np.int64] = np.array(self._handle_column, dtype=np.int64)
        return out

    @property
    def current_displacement(self) -> NDArray[np.float32]:
        """(n, 3) float32 displacement for the handle state set by reset/update."""
        return self._u
