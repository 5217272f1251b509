"""Rig any face, detail transfer (Bickel et al. 2008 §5.4): the template's wrinkle examples carried to a rig.

The target is the sample head re-triangulated and warped into centimetres
(:mod:`workbench.rigging.synthetic`), so the exact map from template to target
vertices (``W``) is known and independent of the transfer's correspondence.
"""

from __future__ import annotations

import numpy as np
import pytest

import workbench
from workbench.methods.wrinkles.family import fit_sample_wrinkles
from workbench.methods.wrinkles.features import vertex_normals
from workbench.methods.wrinkles.layer import blend_weights
from workbench.model import FaceModel, ModelMetadata
from workbench.rigging import DetailMap, RigTransfer, transfer_details
from workbench.rigging import synthetic as syn

WARP = syn.sample_head_warp()


@pytest.fixture(scope="module")
def head() -> FaceModel:
    model = workbench.load_sample("head")
    fit_sample_wrinkles(model)
    return model


@pytest.fixture(scope="module")
def warped(head: FaceModel):
    V2, F2, W = syn.split_remesh(head.vertices, head.faces, seed=1)
    lab = head.component_labels[np.asarray(W.argmax(axis=1)).ravel()]
    target = FaceModel(WARP(V2), F2, component_labels=lab, component_names=head.component_names,
                       metadata=ModelMetadata(name="warped remesh", units="cm"))
    rt = RigTransfer(head, target)
    rig = rt.run().model
    transfer_details(head, rig, rt)
    return rig, W


def _brow_raise(model: FaceModel) -> tuple[np.ndarray, np.ndarray]:
    """World wrinkle detail at the brow-raise example's weights, and the normals there."""
    w = dict(model.wrinkles.example_weights[model.wrinkles.example_names.index("brow_raise")])
    X = blend_weights(model, w)
    return model.wrinkles.details(X).astype(np.float64), vertex_normals(X, model.faces)


def test_a_warped_remesh_gets_the_templates_forehead_wrinkles(head: FaceModel, warped) -> None:
    rig, W = warped
    assert rig.wrinkles.fitted and rig.wrinkles.fresh
    assert rig.wrinkles.example_names == head.wrinkles.example_names
    assert len(rig.handles) == len(head.handles)
    ds, ns = _brow_raise(head)
    dt, nt = _brow_raise(rig)
    mapped = W @ ds  # the template's details at the target's vertices (exact map, not the transfer's)
    mn = W @ ns
    mn /= np.linalg.norm(mn, axis=1, keepdims=True)
    big = np.linalg.norm(ds, axis=1).max()
    forehead = np.linalg.norm(mapped, axis=1) > 0.1 * big
    assert forehead.sum() > 100
    # magnitude: cm on the target, dm on the template; the warp scales by ~1
    ratio = np.sqrt((dt[forehead] ** 2).sum(1).mean()) / 10.0 / np.sqrt((mapped[forehead] ** 2).sum(1).mean())
    assert 0.5 < ratio < 2.0, ratio
    # pattern: the offsets along the normal, where the template has any detail
    region = np.linalg.norm(mapped, axis=1) > 0.02 * big
    corr = np.corrcoef((mapped * mn).sum(1)[region], (dt * nt).sum(1)[region])[0, 1]
    assert corr > 0.7, corr
    # nothing where the template has none
    quiet = np.linalg.norm(mapped, axis=1) < 1e-6 * big
    rms_quiet = np.sqrt((dt[quiet] ** 2).sum(1).mean())
    assert rms_quiet < 0.02 * np.sqrt((dt[forehead] ** 2).sum(1).mean())


def test_onto_the_template_itself_the_details_are_the_templates(head: FaceModel) -> None:
    same = FaceModel(head.vertices, head.faces, component_labels=head.component_labels,
                     component_names=head.component_names, metadata=head.metadata)
    rt = RigTransfer(head, same)
    rig = rt.run().model
    facet = transfer_details(head, rig, DetailMap(rt))
    assert facet is rig.wrinkles
    np.testing.assert_array_equal(rig.handles.vertices, head.handles.vertices)
    for name in head.wrinkles.example_names:
        Xs, Ds = head.wrinkles.example_detailed(name)
        Xt, Dt = rig.wrinkles.example_detailed(name)
        scale = np.abs(Ds - Xs).max()
        assert np.abs((Dt - Xt) - (Ds - Xs)).max() < 0.05 * scale, name
    ds, _ = _brow_raise(head)
    dt, _ = _brow_raise(rig)
    assert np.abs(dt - ds).max() < 0.05 * np.abs(ds).max()


def test_a_template_without_wrinkles_is_fitted_on_a_copy(warped) -> None:
    head = workbench.load_sample("head")
    rig, _ = warped
    small = FaceModel(rig.vertices, rig.faces, list(rig.shapes), component_labels=rig.component_labels,
                      component_names=rig.component_names, metadata=rig.metadata)
    assert not head.wrinkles.fitted
    with pytest.raises(ValueError, match="correspondence maps"):
        transfer_details(head, workbench.load_sample("head"), RigTransfer(head, rig))
    rt = RigTransfer(head, small)
    transfer_details(head, small, rt)
    assert small.wrinkles.fitted
    assert not head.wrinkles.fitted and len(head.handles) == 0  # the template is not changed
