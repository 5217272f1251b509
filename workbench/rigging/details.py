"""Carry the template's wrinkle details onto a rigged face (Bickel et al. 2008 §5.4, issue 16).

Pose-space wrinkles (:mod:`workbench.methods.wrinkles`) learn from *detailed*
example poses: the fine-scale displacement of each example off the blend of its
weights, kept in per-vertex local frames. Those examples live on the
template's vertices, so a face rigged by :func:`~workbench.rigging.transfer_rig`
has none. Bickel et al. §5.4 transfer them with the correspondence: the details
stored in local frames are carried point to point, so they follow the new
surface's orientation.

:func:`transfer_details` does that with the correspondence of a
:class:`~workbench.rigging.RigTransfer` (each target skin vertex: a template
triangle + barycentrics, near and with agreeing normals):

1. every example's world detail on the template ``w = detailed - blend`` is
   interpolated at the target vertex, split into its part along the
   template's normal (at the example's blend) and its tangential part;
2. the normal part goes along the target's normal at the target's blend of the
   same weights, scaled by the units and the fit's local area stretch
   (``sqrt`` of it: a larger face gets proportionally deeper furrows); the
   tangential part goes through the frames and the fit's local Jacobian;
3. target vertices without a template partner (a neck, a bust, parts) get no
   detail;
4. the rig's handles are the template's handles carried to the nearest target
   vertex (names and mirror links kept) when it has none, and its wrinkles are
   fitted from the carried examples (``rig.wrinkles.fit``: one undo step). The
   rig then has the same *Fit wrinkles* state as the template: sliders, handle
   drags and editing work as on the sample head.

The template's examples are its fitted ones (``source.wrinkles``, with any
edits); when it has none, the procedural sample examples are fitted on a copy
of it (the template itself is not changed).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from workbench.geometry.normals import face_normals, vertex_normals
from workbench.model import FaceModel

if TYPE_CHECKING:
    from workbench.methods.wrinkles.facet import WrinklesFacet
    from workbench.rigging.transfer import RigTransfer

__all__ = ["DetailMap", "transfer_details"]


class DetailMap:
    """The correspondence :func:`transfer_details` needs, read from a set-up :class:`RigTransfer`.

    Attributes
    ----------
    target_vertices : (p,) int
        Target vertex ids that have a template partner.
    source_corners : (p, 3) int
        The template vertex ids of each partner triangle.
    bary : (p, 3) float
        Barycentric coordinates in it.
    linear : (p, 3, 3) float
        Template model vectors -> target model vectors at the partner (the
        frames' similarity and the fit's local Jacobian).
    normal_scale : (p,) float
        How a normal offset scales (units and the square root of the local area stretch).
    """

    def __init__(self, transfer: RigTransfer) -> None:
        t = transfer
        sc = t.skin_correspondence
        ok = np.asarray(sc.matched, bool)
        fv = np.asarray(sc.face, np.int64)[ok]
        self.target_vertices = np.asarray(t.tgt.skin_ids, np.int64)[ok]
        self.source_corners = np.asarray(t.src.skin_ids, np.int64)[np.asarray(t.src.skin_faces, np.int64)[fv]]
        self.bary = np.asarray(sc.bary, np.float64)[ok]
        J = np.asarray(sc.jacobians, np.float64)[fv]  # template rest -> fitted, working frame
        s_lin = t.src.frame.scale * t.src.frame.R  # template model -> working
        t_inv = t.tgt.frame.R.T / t.tgt.frame.scale  # working -> target model
        self.linear = t_inv[None] @ J @ s_lin[None]
        # area stretch of the fit in the template's tangent plane: |cof(J) n| for the template's unit normal
        n0 = face_normals(t.src.skin_X, t.src.skin_faces)[fv]
        cof = np.linalg.det(J)[:, None, None] * np.linalg.inv(np.swapaxes(J, 1, 2))
        stretch = np.linalg.norm(np.einsum("pij,pj->pi", cof, n0), axis=1)
        self.normal_scale = (t.src.frame.scale / t.tgt.frame.scale) * np.sqrt(np.clip(stretch, 0.25, 4.0))
        self.n_source = t.source.n_vertices
        self.n_target = t.target.n_vertices
        self._fitted_source = np.asarray(t.fit.positions, np.float64)  # template skin, fitted (working)
        self._src_skin = np.asarray(t.src.skin_ids, np.int64)
        self._tgt_skin = np.asarray(t.tgt.skin_ids, np.int64)
        self._tgt_X = np.asarray(t.tgt.skin_X, np.float64)
        #: (n_target, 3) the target's rest vertices (model units)
        self.target_rest = np.asarray(t.target.vertices, np.float64)

    @classmethod
    def between(cls, correspondence: RigTransfer | DetailMap, source: FaceModel, target: FaceModel,
                what: str) -> DetailMap:
        """The map of ``correspondence``, checked to go from ``source``'s mesh to ``target``'s (``what`` names the caller)."""
        dm = correspondence if isinstance(correspondence, DetailMap) else cls(correspondence)
        if not isinstance(source, FaceModel) or not isinstance(target, FaceModel):
            raise TypeError(f"{what}: source and target must be FaceModels")
        if target.n_vertices != dm.n_target or source.n_vertices != dm.n_source:
            raise ValueError(
                f"{what}: the correspondence maps {dm.n_source} template vertices to {dm.n_target} target "
                f"vertices, got a template of {source.n_vertices} and a target of {target.n_vertices}")
        return dm

    def interpolate(self, field: NDArray[np.float64]) -> NDArray[np.float64]:
        """A per-template-vertex field ``(n_source, c)`` at the mapped target vertices ``(p, c)``."""
        return np.einsum("pk,pkc->pc", self.bary, np.asarray(field, np.float64)[self.source_corners])

    def nearest_target(self, source_vertices: NDArray[np.int64]) -> NDArray[np.int64]:
        """Target vertex nearest to where each template skin vertex was fitted (-1 if not skin)."""
        from scipy.spatial import cKDTree

        local = np.full(self.n_source, -1, np.int64)
        local[self._src_skin] = np.arange(self._src_skin.size)
        li = local[np.asarray(source_vertices, np.int64)]
        out = np.full(li.shape, -1, np.int64)
        ok = li >= 0
        if ok.any():
            _, j = cKDTree(self._tgt_X).query(self._fitted_source[li[ok]])
            out[ok] = self._tgt_skin[j]
        return out

    def carry(self, source_detail: NDArray[np.float64], source_blend: NDArray[np.float64], source_faces: Any,
              target_blend: NDArray[np.float64], target_faces: Any) -> NDArray[np.float64]:
        """World detail on the template (at ``source_blend``) -> world detail on the target (at ``target_blend``)."""
        w = self.interpolate(source_detail)
        ns = self.interpolate(vertex_normals(source_blend, source_faces))
        ns /= np.maximum(np.linalg.norm(ns, axis=1, keepdims=True), 1e-300)
        a = (w * ns).sum(1)
        tang = w - a[:, None] * ns
        nt = vertex_normals(target_blend, target_faces)[self.target_vertices]
        out = np.zeros((self.n_target, 3))
        tang_t = np.einsum("pij,pj->pi", self.linear, tang)
        tang_t -= (tang_t * nt).sum(1, keepdims=True) * nt
        out[self.target_vertices] = (a * self.normal_scale)[:, None] * nt + tang_t
        return out


def _bare_copy(model: FaceModel) -> FaceModel:
    return FaceModel(model.vertices, model.faces, list(model.shapes), polygons=model.polygons,
                     component_labels=model.component_labels, component_names=model.component_names,
                     metadata=model.metadata)


def wrinkled_template(source: FaceModel) -> FaceModel:
    """``source`` when its wrinkles are fitted, else a copy of it with the procedural sample examples fitted
    (the template itself is never changed)."""
    if source.wrinkles.fitted:
        return source
    from workbench.methods.wrinkles.family import fit_sample_wrinkles

    copy = _bare_copy(source)
    fit_sample_wrinkles(copy)
    return copy


def transfer_details(
    source: FaceModel,
    rig: FaceModel,
    correspondence: RigTransfer | DetailMap,
    *,
    examples: list[str] | None = None,
) -> WrinklesFacet:
    """Fit ``rig``'s wrinkles from the template's wrinkle examples carried through the correspondence.

    Parameters
    ----------
    source : FaceModel
        The template (its fitted ``wrinkles``; when it has none the procedural
        sample examples are fitted on a copy of it).
    rig : FaceModel
        The rigged target (``RigTransfer(source, target).run().model``): same
        vertices as the transfer's target, the template's shape names.
    correspondence : RigTransfer or DetailMap
        The transfer that made ``rig`` (its correspondence is read).
    examples : list of str, optional
        Only these of the template's examples (default: all).

    Returns
    -------
    WrinklesFacet
        ``rig.wrinkles``, fitted (one undo step; the carried handles another
        when the rig had none).

    Raises
    ------
    ValueError
        The rig does not belong to the correspondence, misses a shape an
        example uses, or fewer than two examples are left.
    """
    from workbench.methods.handles.handle_set import HandleSet
    from workbench.methods.wrinkles.layer import blend_weights

    dm = DetailMap.between(correspondence, source, rig, "transfer_details")
    src = wrinkled_template(source)
    facet = src.wrinkles
    names = facet.example_names if examples is None else list(examples)
    unknown = [n for n in names if n not in facet.example_names]
    if unknown:
        raise ValueError(f"transfer_details: the template has no wrinkle examples {unknown} "
                         f"(it has {facet.example_names})")
    if len(names) < 2:
        raise ValueError(f"transfer_details: need at least 2 examples, got {names}")
    weights = dict(zip(facet.example_names, facet.example_weights, strict=True))
    missing = sorted({k for n in names for k in weights[n]} - set(rig.shape_names))
    if missing:
        raise ValueError(f"transfer_details: the rig lacks the shapes {missing} the examples use")

    carried: dict[str, tuple[dict[str, float], NDArray[np.float64]]] = {}
    for n in names:
        Xs, Ds = facet.example_detailed(n)
        Xt = blend_weights(rig, weights[n])
        carried[n] = (dict(weights[n]), Xt + dm.carry(Ds - Xs, Xs, src.faces, Xt, rig.faces))

    handles = rig.handles
    if len(handles) == 0:
        hs = src.slot("handles")
        hv = dm.nearest_target(np.asarray(hs.vertices, np.int64))
        keep: list[int] = []
        seen: set[int] = set()
        for i, v in enumerate(hv):
            if v >= 0 and int(v) not in seen:
                seen.add(int(v))
                keep.append(i)
        new_index = np.full(len(hv), -1, np.int64)
        new_index[keep] = np.arange(len(keep))
        mirror = np.asarray(hs.mirror, np.int64)[keep]
        mirror = np.where(mirror >= 0, new_index[np.maximum(mirror, 0)], -1)
        handles.set(HandleSet(hv[keep].astype(np.int32), np.zeros((len(keep), 3), np.float32),
                              tuple(hs.names[i] for i in keep), mirror.astype(np.int32)),
                    label="Handles from the template")
    rig.wrinkles.fit(carried)
    return rig.wrinkles
