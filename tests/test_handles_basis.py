"""``model.handles.basis()``: the public shell basis a view evaluates the handle layer with."""

from __future__ import annotations

import numpy as np

import workbench
from workbench.methods.handles.presets import default_face_handles
from workbench.model import HandleSet


def test_basis_times_mean_offsets_is_the_handle_layer() -> None:
    model = workbench.load_sample("head")
    hs = default_face_handles(model)
    # a duplicated handle vertex shares one column
    verts = np.append(hs.vertices, hs.vertices[0])
    names = (*hs.names, "dup")
    model.handles.set(HandleSet(verts, np.zeros((verts.size, 3), np.float32), names,
                                np.append(hs.mirror, -1)))
    rng = np.random.default_rng(3)
    offsets = (rng.normal(size=(verts.size, 3)) * 0.02).astype(np.float32)
    model.handles.set_offsets(offsets)
    B, columns = model.handles.basis()
    assert B.shape == (model.n_vertices, verts.size - 1) and B.dtype == np.float32
    assert not B.flags.writeable
    assert columns.shape == (verts.size,) and columns[-1] == columns[0]
    u = np.zeros((B.shape[1], 3))
    np.add.at(u, columns, offsets.astype(np.float64))
    u /= np.bincount(columns, minlength=B.shape[1])[:, None]
    got = B @ u.astype(np.float32)
    np.testing.assert_allclose(got, model.handles.displacement(), atol=1e-6)
