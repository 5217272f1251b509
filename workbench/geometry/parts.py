"""What each mesh component of a face is: skin, eyeball, lashes, teeth, tongue ...

Every tool treats the parts of a head differently — the shell solve keeps the
eyeballs in place and lets the lashes ride on the lids, the region segmentation
gives eyeballs, teeth and tongue a region of their own, the viewport and the
renders draw eyeballs white and teeth ivory. They all ask this module, once per
mesh, through :func:`component_roles` (``model.part_roles`` on a model).

**Names first.** A component whose name says what it is gets that role
(:func:`role_from_name`: ``"eye_left"`` → ``"eyeball_left"``, ``"EyeLashes"`` →
``"lashes"``, ``"teeth_upper"``, ``"Tongue"``, ``"skin"``/``"head"``/``"face"``/``"body"``
→ ``"skin"``, ...). Names that say nothing (``"mesh_0"``, ``"component_3"``,
``"Object.001"``) are recognised by geometry:

1. **Skin** — the unnamed component with the largest surface area (unless a
   component is named skin); other open surfaces at least 30 % of its area are
   skin too.
2. **Eyeballs** — closed near-spheres (each connected piece: at most 5 % of its
   edges on a boundary, median ``|‖p − c‖ − r| / r`` ≤ 0.05 for the
   least-squares sphere ``c, r``, directions from ``c`` covering the sphere),
   with a radius of 0.3–10 % of the skin's bounding-box diagonal and the centre
   inside that box. When there are more than two, the pair most alike in radius
   and most mirror-symmetric about the skin's mid-plane wins. The face's mid-plane
   is then the one half-way between the eyes (the skin's box is off it when a
   bust or a warp makes the shoulders lopsided: on generated foreign faces that
   put both eyes on one side in 8 of 20, and their teeth and tongue off the
   face). The side is that of the centre along the lateral axis ``up × front``
   (the subject's left, from ``metadata.up_axis`` / ``front_axis``); a component
   holding both is ``"eyeball"``.
3. **Mouth interior** — with the eyes as the yardstick (inter-ocular distance
   ``d``; without eyes the nose tip, the skin's front-most vertex, and ``d`` =
   0.35 × the skin's width): a component centred near the mid-plane (within
   0.4 ``d``: a head rolled 10° moves the mouth ~0.2 ``d`` sideways of the eyes'
   middle), 0.4–2.2 ``d`` below the eyes, lying behind the skin in front of it
   (enclosed by the lips). Teeth are arches — seen from above, the centroid lies
   in the empty middle of a U, covered by none of its triangles; a tongue is a
   solid blob that covers its centroid. Two teeth arches are ``"teeth_upper"``
   and ``"teeth_lower"`` by height, one is ``"teeth"``.
4. **Lashes** — small, non-spherical parts whose vertices all lie within
   2.2 eyeball radii of an eyeball centre (strips on the lids).
5. **Brows** — thin strips (smallest principal extent < 30 % of the largest)
   lying on the skin (median distance to it < half an eyeball radius), 0.8–4 eyeball
   radii above an eye.
6. Anything else is ``"other"``.

The categories the tools use: :data:`RIGID_ROLES` (eyeballs, teeth, tongue:
rigid parts with a region of their own), :data:`ATTACHED_ROLES` (lashes, brows,
hair and unrecognised small parts: they follow the nearest skin).
"""

from __future__ import annotations

import re
import weakref
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from workbench.geometry.axes import AxesError, head_axes
from workbench.geometry.normals import triangle_areas

if TYPE_CHECKING:
    from workbench.core.shapes import ModelMetadata

__all__ = [
    "ATTACHED_ROLES",
    "RIGID_ROLES",
    "ROLES",
    "component_roles",
    "model_part_roles",
    "part_material",
    "role_from_name",
    "role_side",
]

#: every role :func:`component_roles` gives
ROLES = (
    "skin",
    "eyeball_left",
    "eyeball_right",
    "eyeball",
    "lashes",
    "brows",
    "hair",
    "teeth_upper",
    "teeth_lower",
    "teeth",
    "tongue",
    "other",
)
#: rigid parts: own region, never segmented, not on the skin
RIGID_ROLES = frozenset({"eyeball_left", "eyeball_right", "eyeball", "teeth_upper", "teeth_lower", "teeth", "tongue"})
#: surface attachments: they follow the nearest skin vertex
ATTACHED_ROLES = frozenset({"lashes", "brows", "hair", "other"})

_SIDE_LEFT = re.compile(r"left|(^|[^a-z])l($|[^a-z])|(?<=[a-z])L$|(?<=[a-z])_L\b", re.IGNORECASE)
_SIDE_RIGHT = re.compile(r"right|(^|[^a-z])r($|[^a-z])|(?<=[a-z])R$|(?<=[a-z])_R\b", re.IGNORECASE)

#: (pattern, role) in the order they are tried; the first match wins
_NAME_RULES: tuple[tuple[re.Pattern[str], str], ...] = (
    (re.compile(r"lash", re.IGNORECASE), "lashes"),
    (re.compile(r"eye_?brow|brow_?hair|brows?($|[^a-z])", re.IGNORECASE), "brows"),
    (re.compile(r"hair|beard|moustache|mustache|stubble", re.IGNORECASE), "hair"),
    (re.compile(r"teeth|tooth|gum", re.IGNORECASE), "teeth"),
    (re.compile(r"tongue", re.IGNORECASE), "tongue"),
    (re.compile(r"eye|iris|pupil|cornea|sclera", re.IGNORECASE), "eyeball"),
    (re.compile(r"skin|head|face|body", re.IGNORECASE), "skin"),
)
_UPPER = re.compile(r"upper|top|(^|[^a-z])up($|[^a-z])|maxill", re.IGNORECASE)
_LOWER = re.compile(r"lower|bottom|(^|[^a-z])low($|[^a-z])|mandib|jaw", re.IGNORECASE)


def role_from_name(name: str) -> str | None:
    """The role a component name says, or None if it says nothing.

    Parameters
    ----------
    name : str
        Component name (``"eye_left"``, ``"Teeth_Upper"``, ``"mesh_3"``).

    Returns
    -------
    str or None
        One of :data:`ROLES` (never ``"other"``); eyeballs and teeth get their
        side / jaw when the name tells it (``"eyeball_left"``, ``"teeth_lower"``).
    """
    for pattern, role in _NAME_RULES:
        if not pattern.search(name):
            continue
        if role == "eyeball":
            if _SIDE_LEFT.search(name):
                return "eyeball_left"
            if _SIDE_RIGHT.search(name):
                return "eyeball_right"
        elif role == "teeth":
            if _UPPER.search(name):
                return "teeth_upper"
            if _LOWER.search(name):
                return "teeth_lower"
        return role
    return None


def role_side(role: str) -> str:
    """``"_L"``, ``"_R"`` or ``""`` for a role (region names use it)."""
    return "_L" if role.endswith("_left") else "_R" if role.endswith("_right") else ""


def part_material(role: str, name: str = "") -> str:
    """The look of a part, for colours: ``"skin"``, ``"eye"``, ``"eyelashes"``, ``"eyebrows"``, ``"teeth"``, ``"gums"``, ``"tongue"``.

    Parameters
    ----------
    role : str
        One of :data:`ROLES`.
    name : str, optional
        The component name: gums are teeth by role but pink (``"gum"`` in the name).
    """
    if "gum" in name.lower():
        return "gums"
    if role.startswith("eyeball"):
        return "eye"
    if role.startswith("teeth"):
        return "teeth"
    return {"lashes": "eyelashes", "brows": "eyebrows", "hair": "eyebrows", "tongue": "tongue"}.get(role, "skin")


# --------------------------------------------------------------------------- geometry


def _frame(metadata: ModelMetadata | None) -> NDArray[np.float64]:
    """(3, 3) rows: lateral (the subject's left = up × front), up, front."""
    try:
        return head_axes(getattr(metadata, "up_axis", "+y") or "+y", getattr(metadata, "front_axis", "+z") or "+z")
    except AxesError:  # degenerate metadata: fall back to +y up, +z front
        return head_axes("+y", "+z")


def _triangle_areas(V: NDArray[np.float64], F: NDArray[np.int64]) -> NDArray[np.float64]:
    return triangle_areas(V, F) if F.size else np.zeros(0)


def _boundary_fraction(F: NDArray[np.int64]) -> float:
    """Share of the undirected edges of ``F`` used by one face only (0 for a closed surface)."""
    if F.size == 0:
        return 1.0
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e[:, 0] * (int(F.max()) + 1) + e[:, 1], return_counts=True)
    return float((counts == 1).sum() / counts.size)


def _fit_sphere(P: NDArray[np.float64]) -> tuple[NDArray[np.float64], float, float, float]:
    """Least-squares sphere through ``P``: (centre, radius, median |d - r| / r, |mean unit direction|)."""
    if P.shape[0] < 4:
        return P.mean(axis=0) if P.size else np.zeros(3), 0.0, np.inf, 1.0
    A = np.c_[2.0 * P, np.ones(P.shape[0])]
    sol, *_ = np.linalg.lstsq(A, (P**2).sum(axis=1), rcond=None)
    c = sol[:3]
    r2 = float(sol[3] + c @ c)
    if not np.isfinite(r2) or r2 <= 0:
        return c, 0.0, np.inf, 1.0
    r = float(np.sqrt(r2))
    d = np.linalg.norm(P - c, axis=1)
    res = float(np.median(np.abs(d - r)) / r)
    dirs = (P - c) / np.maximum(d, 1e-300)[:, None]
    return c, r, res, float(np.linalg.norm(dirs.mean(axis=0)))


class _Part:
    """Measurements of one component (in the lateral/up/front frame)."""

    def __init__(self, V: NDArray[np.float64], F: NDArray[np.int64], ids: NDArray[np.intp]) -> None:
        self.ids = ids
        self.P = V[ids]
        self.F = F
        self.area = float(_triangle_areas(V, F).sum())
        self.boundary = _boundary_fraction(F)
        w = np.zeros(V.shape[0])
        if F.size:
            a = _triangle_areas(V, F) / 3.0
            for k in range(3):
                w += np.bincount(F[:, k], weights=a, minlength=V.shape[0])
        wi = w[ids]
        self.centroid = (self.P * wi[:, None]).sum(0) / wi.sum() if wi.sum() > 0 else self.P.mean(0)
        X = self.P - self.P.mean(0)
        self.extents = np.sort(np.sqrt(np.maximum(np.linalg.eigvalsh(X.T @ X / max(len(X), 1)), 0.0)))[::-1]
        self._V = V
        self._fitted = False
        self._spheres: list[tuple[NDArray[np.float64], float]] | None = None

    @property
    def spheres(self) -> list[tuple[NDArray[np.float64], float]] | None:
        """(centre, radius) of every connected piece if each is a closed near-sphere, else None (fitted on first use)."""
        if not self._fitted:
            self._spheres = self._piece_spheres(self._V, self.F, self.ids)
            self._fitted = True
        return self._spheres

    @staticmethod
    def _piece_spheres(
        V: NDArray[np.float64], F: NDArray[np.int64], ids: NDArray[np.intp]
    ) -> list[tuple[NDArray[np.float64], float]] | None:
        """(centre, radius) of every connected piece if each is a closed near-sphere, else None."""
        if F.size == 0 or ids.size < 8:
            return None
        local = np.full(V.shape[0], -1, np.int64)
        local[ids] = np.arange(ids.size)
        Fl = local[F]
        if (Fl < 0).any():
            return None
        n = ids.size
        adj = sp.coo_matrix((np.ones(Fl.size), (np.repeat(Fl[:, 0], 3), Fl.ravel())), shape=(n, n))
        k, lab = connected_components(adj + adj.T, directed=False)
        if k > 4:
            return None
        out = []
        for p in range(k):
            sel = lab == p
            Fp = Fl[sel[Fl[:, 0]]]
            if _boundary_fraction(Fp) > 0.05:
                return None
            c, r, res, cover = _fit_sphere(V[ids[sel]])
            if r <= 0 or res > 0.05 or cover > 0.35:
                return None
            out.append((c, r))
        return out


def component_roles(
    V: ArrayLike,
    F: ArrayLike,
    labels: ArrayLike,
    names: Sequence[str],
    metadata: ModelMetadata | None = None,
) -> list[str]:
    """The role of every mesh component: names first, else geometry (see the module docstring).

    Parameters
    ----------
    V : (n, 3) float
        Neutral vertex positions.
    F : (m, 3) int
        Triangles.
    labels : (n,) int
        Component of each vertex, indexing ``names``.
    names : sequence of str
        One name per component (``len(names) > labels.max()``).
    metadata : ModelMetadata, optional
        ``up_axis`` / ``front_axis`` give the lateral axis (default ``+y`` up, ``+z`` front).

    Returns
    -------
    list of str
        ``len(names)`` roles from :data:`ROLES`.
    """
    V = np.asarray(V, dtype=np.float64).reshape(-1, 3)
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    labels = np.asarray(labels, dtype=np.int64).reshape(-1)
    k = len(names)
    if labels.shape[0] != V.shape[0]:
        raise ValueError(f"labels: expected {V.shape[0]} entries, got {labels.shape[0]}")
    if k == 0:
        return []
    if labels.size and (labels.min() < 0 or labels.max() >= k):
        raise ValueError(f"labels must index into the {k} names")
    roles: list[str | None] = [role_from_name(str(nm)) for nm in names]
    unknown = [c for c in range(k) if roles[c] is None]
    if not unknown and all(r != "eyeball" for r in roles):
        return [r or "other" for r in roles]

    R = _frame(metadata)
    Vf = V @ R.T  # columns: lateral, up, front
    face_comp = labels[F[:, 0]] if F.size else np.zeros(0, np.int64)
    parts: dict[int, _Part] = {}

    def part(c: int) -> _Part:
        if c not in parts:
            parts[c] = _Part(Vf, F[face_comp == c], np.flatnonzero(labels == c))
        return parts[c]

    present = [c for c in range(k) if (labels == c).any()]
    # 1. skin
    skin = [c for c in present if roles[c] == "skin"]
    if not skin:
        cand = [c for c in present if roles[c] is None]
        if cand:
            big = max(cand, key=lambda c: part(c).area)
            roles[big] = "skin"
            skin = [big]
            for c in cand:
                if c != big and part(c).boundary > 0.0 and part(c).area >= 0.3 * part(big).area:
                    roles[c] = "skin"
                    skin.append(c)
    unknown = [c for c in present if roles[c] is None]
    named_eyes = [c for c in present if (roles[c] or "").startswith("eyeball")]
    if not skin or (not unknown and not any(roles[c] == "eyeball" for c in named_eyes)):
        return [r or "other" for r in roles]
    skin_ids = np.flatnonzero(np.isin(labels, skin))
    S = Vf[skin_ids]
    lo, hi = S.min(axis=0), S.max(axis=0)
    diag = float(np.linalg.norm(hi - lo)) or 1.0
    mid = 0.5 * float(lo[0] + hi[0])

    # 2. eyeballs: named ones, then closed near-spheres among the unknown
    eyes: list[tuple[int, NDArray[np.float64], float]] = []  # (component, centre, radius) per sphere
    for c in named_eyes:
        for centre, r in _spheres_or_fit(part(c)):
            eyes.append((c, centre, r))
    cands: list[tuple[int, NDArray[np.float64], float]] = []
    for c in unknown:
        sph = part(c).spheres
        if not sph:
            continue
        if all(0.003 * diag <= r <= 0.1 * diag and np.all(cen >= lo) and np.all(cen <= hi) for cen, r in sph):
            cands += [(c, cen, r) for cen, r in sph]
    if cands:
        chosen = _pick_eyes(cands, mid) if not eyes else [e for e in cands if e[0] in _pair_with(eyes, cands, mid)]
        for c in {e[0] for e in chosen}:
            roles[c] = "eyeball"
        eyes += chosen
    if len(eyes) >= 2:
        # the face's midline is between its eyes: the skin's box is off it when a bust or a
        # warp makes the shoulders lopsided (both eyes on one side of the box's middle)
        mid = 0.5 * float(min(e[1][0] for e in eyes) + max(e[1][0] for e in eyes))
    for c in {e[0] for e in eyes}:
        if roles[c] == "eyeball":
            sides = {np.sign(cen[0] - mid) for cc, cen, _ in eyes if cc == c}
            if sides == {1.0}:
                roles[c] = "eyeball_left"
            elif sides == {-1.0}:
                roles[c] = "eyeball_right"
    unknown = [c for c in present if roles[c] is None]
    if not unknown:
        return [r or "other" for r in roles]

    # the face's yardstick: eye level and inter-ocular distance
    if eyes:
        centres = np.array([e[1] for e in eyes])
        r_eye = float(np.mean([e[2] for e in eyes]))
        eye_up = float(centres[:, 1].mean())
        lat = np.abs(centres[:, 0] - mid)
        iod = 2.0 * float(lat.mean()) if lat.mean() > r_eye else 0.35 * float(hi[0] - lo[0])
    else:
        centres = np.zeros((0, 3))
        r_eye = 0.0
        iod = 0.35 * float(hi[0] - lo[0])
        nose = S[np.argmax(S[:, 2])]
        eye_up = float(nose[1]) + 0.5 * iod
    skin_tree = cKDTree(S)

    # 3. mouth interior
    teeth: list[int] = []
    for c in unknown:
        p = part(c)
        cen = p.centroid
        if abs(cen[0] - mid) > 0.4 * iod or not (eye_up - 2.2 * iod <= cen[1] <= eye_up - 0.4 * iod):
            continue
        # enclosed: skin in front of it (the lips), within a window around its centre
        win = np.flatnonzero((np.abs(S[:, 0] - cen[0]) < 0.3 * iod) & (np.abs(S[:, 1] - cen[1]) < 0.3 * iod))
        if win.size == 0 or S[win, 2].max() < p.P[:, 2].max() - 0.1 * iod:
            continue
        if _covers_from_above(Vf, p.F, cen):
            roles[c] = "tongue"
        else:
            teeth.append(c)
    if len(teeth) == 1:
        roles[teeth[0]] = "teeth"
    elif teeth:
        order = sorted(teeth, key=lambda c: part(c).centroid[1])
        roles[order[-1]] = "teeth_upper"
        roles[order[0]] = "teeth_lower"
        for c in order[1:-1]:
            roles[c] = "teeth"

    # 4./5. lashes and brows, measured from the eyes
    for c in [c for c in present if roles[c] is None]:
        p = part(c)
        if eyes:
            d = np.linalg.norm(p.P[:, None, :] - centres[None, :, :], axis=2)
            nearest = np.argmin(d.mean(axis=0))
            if float(d[:, nearest].max()) <= 2.2 * r_eye and p.area < 3.0 * 4.0 * np.pi * r_eye**2:
                roles[c] = "lashes"
                continue
            above = p.centroid[1] - centres[:, 1]
            dist_skin = float(np.median(skin_tree.query(p.P)[0]))
            near_x = np.abs(p.centroid[0] - centres[:, 0]) < 2.5 * r_eye
            if (
                p.extents[-1] < 0.3 * p.extents[0]
                and dist_skin < 0.5 * r_eye
                and bool(np.any(near_x & (above >= 0.8 * r_eye) & (above <= 4.0 * r_eye)))
            ):
                roles[c] = "brows"
                continue
        roles[c] = "other"
    return [r or "other" for r in roles]


def _covers_from_above(Vf: NDArray[np.float64], F: NDArray[np.int64], point: NDArray[np.float64]) -> bool:
    """Whether some triangle of ``F``, seen along the up axis, covers ``point`` (a solid blob, not an arch)."""
    if F.size == 0:
        return False
    P = Vf[:, [0, 2]][F]  # (m, 3, 2): lateral and front
    q = point[[0, 2]]
    a, b, c = P[:, 0], P[:, 1], P[:, 2]
    v0, v1, v2 = c - a, b - a, q - a
    d00 = (v0 * v0).sum(1)
    d01 = (v0 * v1).sum(1)
    d11 = (v1 * v1).sum(1)
    d20 = (v2 * v0).sum(1)
    d21 = (v2 * v1).sum(1)
    den = d00 * d11 - d01 * d01
    ok = np.abs(den) > 1e-300
    den = np.where(ok, den, 1.0)
    u = (d11 * d20 - d01 * d21) / den
    v = (d00 * d21 - d01 * d20) / den
    return bool(np.any(ok & (u >= 0) & (v >= 0) & (u + v <= 1)))


def _spheres_or_fit(p: _Part) -> list[tuple[NDArray[np.float64], float]]:
    if p.spheres:
        return p.spheres
    c, r, _, _ = _fit_sphere(p.P)
    return [(c, r)] if r > 0 else []


def _pick_eyes(
    cands: list[tuple[int, NDArray[np.float64], float]], mid: float
) -> list[tuple[int, NDArray[np.float64], float]]:
    """The two spheres most alike and most mirror-symmetric about ``mid`` (one if there is one)."""
    if len(cands) <= 2:
        return cands
    best, best_cost = (0, 1), np.inf
    for i in range(len(cands)):
        for j in range(i + 1, len(cands)):
            (_, ci, ri), (_, cj, rj) = cands[i], cands[j]
            mirrored = cj.copy()
            mirrored[0] = 2 * mid - mirrored[0]
            cost = abs(ri - rj) / max(ri, rj) + float(np.linalg.norm(ci - mirrored)) / max(ri, rj)
            if cost < best_cost:
                best, best_cost = (i, j), cost
    return [cands[best[0]], cands[best[1]]]


def _pair_with(
    eyes: list[tuple[int, NDArray[np.float64], float]], cands: list[tuple[int, NDArray[np.float64], float]], mid: float
) -> set[int]:
    """Candidates that mirror a named eye (the unnamed other eye)."""
    out: set[int] = set()
    for _, ce, re_ in eyes:
        m = ce.copy()
        m[0] = 2 * mid - m[0]
        for c, cc, rc in cands:
            if np.linalg.norm(cc - m) < 0.5 * re_ and abs(rc - re_) < 0.25 * re_:
                out.add(c)
    return out


# --------------------------------------------------------------------------- per model, cached

_CACHE: weakref.WeakKeyDictionary[Any, tuple[tuple[Any, ...], tuple[str, ...]]] = weakref.WeakKeyDictionary()


def model_part_roles(model: Any) -> tuple[str, ...]:
    """:func:`component_roles` of a model or a pipeline ``StateView`` (computed once per mesh).

    Parameters
    ----------
    model : FaceModel or StateView
        Anything with ``vertices``, ``faces``, ``component_labels``,
        ``component_names`` and ``metadata``.

    Returns
    -------
    tuple of str
        One role per component name.
    """
    owner = getattr(model, "_state", model)  # a StateView reads its state's mesh
    V, F, labels = model.vertices, model.faces, model.component_labels
    names = tuple(model.component_names)
    meta = getattr(model, "metadata", None)
    key = (id(V), id(F), id(labels), names, getattr(meta, "up_axis", None), getattr(meta, "front_axis", None))
    try:
        hit = _CACHE.get(owner)
    except TypeError:  # not weak-referenceable: compute every time
        return tuple(component_roles(V, F, labels, names, meta))
    if hit is not None and hit[0] == key:
        return hit[1]
    roles = tuple(component_roles(V, F, labels, names, meta))
    _CACHE[owner] = (key, roles)
    return roles
