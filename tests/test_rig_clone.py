"""Expression cloning (``workbench.rigging.clone_animation``, Noh & Neumann 2001; issue 29).

A performance of the sample head (a realistic take: dense, co-articulated
weights) is cloned onto faces whose true performance is known exactly
(:mod:`workbench.testing`: ``face.pose(weights)``): the head itself, the head
warped with its triangles cut the other way and its vertices renumbered, and the
same in millimetres. Errors are the mean vertex error over the mean motion,
median over frames.
"""

from __future__ import annotations

import igl
import numpy as np
import pytest
import scipy.sparse as sp

import workbench
from workbench.geometry.normals import vertex_normals
from workbench.model import FaceModel
from workbench.rigging import ExpressionCloner, clone_animation
from workbench.rigging.clone import local_scales
from workbench.rigging.clone_motion import field_deformation, local_deformation
from workbench.testing import compose, in_units, proportions_warp, renumbered, warped
from workbench.testing.grids import grid_triangles, grid_vertices
from workbench.testing.takes import realistic_weights
from workbench.testing.warps import random_warp

T = 24


@pytest.fixture(scope="module")
def head():
    return workbench.load_sample("head")


@pytest.fixture(scope="module")
def take(head):
    W = realistic_weights(head, T, seed=1)
    names = list(head.shape_names)
    deltas = np.stack([head.shape(n).delta for n in names]).astype(np.float64)
    frames = head.vertices + np.einsum("tk,knc->tnc", W, deltas)
    return names, W, frames


@pytest.fixture(scope="module")
def foreign(head):
    """The head warped, its quads cut along the other diagonal and its vertices renumbered."""
    return renumbered(warped(head, random_warp(head.vertices, seed=3), shapes=False, retriangulate=True), seed=2)


def _error(pred, face, names, W):
    truth = np.stack([face.pose(dict(zip(names, w, strict=True))) for w in W])
    motion = np.linalg.norm(truth - face.model.vertices, axis=2).mean(1)
    moving = motion > 1e-9 * motion.max()  # a rest frame has no motion to be relative to
    return float(np.median(np.linalg.norm(pred - truth, axis=2).mean(1)[moving] / motion[moving]))


def test_cloning_onto_the_source_itself_gives_the_performance_back(head, take) -> None:
    _, _, frames = take
    out = clone_animation(frames, head, warped(head, shapes=False).model)  # the same mesh, no shapes
    motion = np.abs(frames - head.vertices).max()
    assert out.shape == frames.shape
    np.testing.assert_allclose(out, frames, atol=1e-6 * motion + 1e-9)


def test_cloning_onto_a_warped_renumbered_face_follows_its_true_performance(head, take, foreign) -> None:
    names, W, frames = take
    steps = []
    cloner = ExpressionCloner(head, foreign.model, progress=lambda f, m: steps.append(f))
    out = cloner.clone(frames)
    assert steps and steps[-1] == 1.0 and steps == sorted(steps)
    err = _error(out, foreign, names, W)
    assert err <= 0.05, err  # the issue: 10 % of the motion, 5 % on generated faces
    # the paper's motion model as printed, on the same correspondence: the default is closer
    err_frames = _error(cloner.with_motion("frames").clone(frames), foreign, names, W)
    assert err < err_frames, (err, err_frames)
    # the naive peer: every target vertex copies the motion of the nearest source vertex
    # (after the same rigid alignment) - cloning must do much better
    copy = cloner.nearest_copy(frames)
    err_copy = _error(copy, foreign, names, W)
    assert err < 0.5 * err_copy, (err, err_copy)
    # the per-frame deformation-transfer peer lands near the truth too, and cloning is no worse
    err_dt = _error(cloner.deformation_transfer(frames), foreign, names, W)
    assert err_dt < 0.5 * err_copy and err <= 1.1 * err_dt, (err, err_dt, err_copy)


def test_the_clone_is_in_the_targets_units(head, take, foreign) -> None:
    names, W, frames = take
    cm = in_units(foreign, "mm")
    out = clone_animation(frames, head, cm.model)
    err = _error(out, cm, names, W)
    assert err <= 0.10, err
    assert np.abs(out - cm.model.vertices).max() > 50 * np.abs(frames - head.vertices).max()  # dm -> mm


def test_a_face_with_a_grown_jaw_follows_its_true_performance(head, take) -> None:
    """Jaw 1.25x and eyes 1.15x about their centres, warped, renumbered, in mm: the fit must stretch.

    Point-to-point non-rigid ICP alone leaves the grown jaw under-stretched (0.25 of the
    motion); the cloner's point-to-plane tail lets the template slide along the target.
    """
    names, W, frames = take
    prop = compose(proportions_warp(head, eyes=1.15, jaw=1.25), random_warp(head.vertices, seed=5))
    face = in_units(renumbered(warped(head, prop, shapes=False), seed=4), "mm")
    cloner = ExpressionCloner(head, face.model)
    err = _error(cloner.clone(frames), face, names, W)
    err_copy = _error(cloner.nearest_copy(frames), face, names, W)
    err_ring = _error(cloner.with_motion("affine").clone(frames), face, names, W)
    print(f"grown jaw: field {err:.4f}, one-ring affine {err_ring:.4f}, copy {err_copy:.4f}")
    assert err <= 0.13, err
    assert err < 0.5 * err_copy, (err, err_copy)
    # the one-ring map cannot see how the grown jaw stretches along its normal; the field can
    assert err < 0.9 * err_ring, (err, err_ring)


def test_field_deformation_of_an_affine_map_is_the_map_normal_stretch_included() -> None:
    # a curved sheet under a 3-D affine map that also stretches along the sheet's normal: the
    # thin-plate field reproduces it exactly (its affine part), from all or from trusted points only;
    # the one-ring map sees only the tangential columns
    V = grid_vertices(9, x=(0.0, 1.0), y=(0.0, 1.0), height=lambda x, y: 0.3 * np.sin(3 * x) * np.cos(2 * y))
    F = grid_triangles(9)
    M = np.array([[1.1, 0.2, 0.0], [-0.1, 0.9, 0.3], [0.0, 0.1, 1.8]])
    X1 = V @ M.T + [0.2, -0.1, 0.5]
    for trusted in (None, np.arange(len(V)) % 3 != 0):
        J = field_deformation(V, X1, trusted=trusted, smoothing=0.0)
        np.testing.assert_allclose(J, np.broadcast_to(M, J.shape), atol=1e-6)
    A = sp.csr_matrix(igl.adjacency_matrix(F)).astype(float)
    ring = local_deformation(V, X1, F, A, vertex_normals(V, F), vertex_normals(X1, F), smoothing=0.0)
    assert np.abs(ring - M).max() > 0.1


def test_the_planar_tail_keeps_a_fit_that_is_already_on_the_surface(head) -> None:
    """The template lying on the target (the same surface): no step moves it (sliding costs bending)."""
    from workbench.geometry.surface import SurfaceQuery
    from workbench.rigging.registration import planar_refine

    V, F = np.asarray(head.vertices, np.float64), np.asarray(head.faces)
    skin = head.component_vertices("skin")
    keep = np.isin(F, skin).all(axis=1)
    used = np.unique(F[keep])
    remap = np.full(V.shape[0], -1)
    remap[used] = np.arange(used.size)
    X, Fs = V[used], remap[F[keep]]
    out = planar_refine(X, X, Fs, SurfaceQuery(X, Fs))
    size = float(np.linalg.norm(np.ptp(X, axis=0)))
    assert out.iterations == 20
    assert np.abs(out.positions - X).max() < 1e-6 * size


def test_local_scales_of_a_uniformly_grown_surface_are_its_growth() -> None:
    # a bumpy grid grown 1.5x about the origin: every one-ring's box grows 1.5x, rotation none
    V = grid_vertices(9, x=(0.0, 1.0), y=(0.0, 1.0), height=lambda x, y: 0.05 * np.sin(6 * x) * np.cos(5 * y))
    F = grid_triangles(9)
    A = sp.csr_matrix(igl.adjacency_matrix(F)).astype(float)
    R = np.broadcast_to(np.eye(3), (len(V), 3, 3)).copy()
    frames = np.broadcast_to(np.eye(3), (len(V), 3, 3)).copy()
    S = local_scales(V, 1.5 * V, A, R, frames)
    np.testing.assert_allclose(S, 1.5, rtol=1e-9)
    # and the identity leaves every scale at 1
    np.testing.assert_allclose(local_scales(V, V, A, R, frames), 1.0, rtol=1e-12)


def test_local_deformation_of_a_similarity_is_the_similarity_and_a_shear_is_kept() -> None:
    V = grid_vertices(9, x=(0.0, 1.0), y=(0.0, 1.0), height=lambda x, y: 0.05 * np.sin(6 * x) * np.cos(5 * y))
    F = grid_triangles(9)
    A = sp.csr_matrix(igl.adjacency_matrix(F)).astype(float)
    c, s_ = np.cos(0.4), np.sin(0.4)
    R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
    N0 = vertex_normals(V, F)
    for M in (np.eye(3), 1.5 * np.eye(3), 0.7 * R):
        J = local_deformation(V, V @ M.T, F, A, N0, vertex_normals(V @ M.T, F), smoothing=0.0)
        np.testing.assert_allclose(J, np.broadcast_to(M, J.shape), atol=1e-9)
        # smoothing keeps a constant field
        J = local_deformation(V, V @ M.T, F, A, N0, vertex_normals(V @ M.T, F), smoothing=0.05)
        np.testing.assert_allclose(J, np.broadcast_to(M, J.shape), atol=1e-9)
    # a shear of a flat sheet: every in-plane edge maps exactly as the shear maps it
    flat = V * [1.0, 1.0, 0.0]
    H = np.array([[1.0, 0.3, 0.0], [0.0, 1.2, 0.0], [0.0, 0.0, 1.0]])
    J = local_deformation(flat, flat @ H.T, F, A, vertex_normals(flat, F), vertex_normals(flat @ H.T, F), 0.0)
    np.testing.assert_allclose(J[:, :2, :2], np.broadcast_to(H[:2, :2], (len(V), 2, 2)), atol=1e-9)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda f: f[:, :-1], r"frames must have shape \(T, 5084, 3\)"),
        (lambda f: f[:0], "frames is empty"),
        (lambda f: np.where(np.arange(len(f))[:, None, None] == 3, np.nan, f), r"frames \[3\] hold NaN"),
    ],
)
def test_bad_frames_are_named_before_any_set_up(head, take, make, match) -> None:
    _, _, frames = take
    with pytest.raises(ValueError, match=match):
        clone_animation(make(frames), head, "/nonexistent/target.obj")  # fails before reading the target


def test_a_source_without_shapes_a_plain_animated_mesh_clones_too(head, take) -> None:
    _, _, frames = take
    plain = FaceModel(head.vertices, head.faces, component_labels=head.component_labels,
                      component_names=head.component_names, metadata=head.metadata)
    out = clone_animation(frames[:4], plain, head)
    np.testing.assert_allclose(out, frames[:4], atol=1e-6 * np.abs(frames - head.vertices).max())


# ------------------------------------------------------------------ workbench clone
def _performance_file(head, folder):
    """The sample head with jawOpen and a smile keyed over 1 s, saved as a .fwb."""
    perf = workbench.load_sample("head")
    for t, jaw, smile in ((0.0, 0.0, 0.0), (0.5, 1.0, 0.3), (1.0, 0.2, 0.8)):
        perf.set_weights({"jawOpen": jaw, "mouthSmileLeft": smile})
        perf.timeline.key_weights(t, ["jawOpen", "mouthSmileLeft"], interpolation="linear")
    path = folder / "performance.fwb"
    perf.save(path)
    return perf, path


def test_clone_command_writes_a_point_cache_that_plays_the_clone(head, foreign, tmp_path) -> None:
    from workbench.cli import main
    from workbench.export.pointcache import PC2_HEADER

    perf, perf_path = _performance_file(head, tmp_path)
    target = tmp_path / "target.fwb"
    foreign.model.save(target)
    out = tmp_path / "cloned.pc2"
    assert main(["clone", str(perf_path), str(target), "--out", str(out)]) == 0
    raw = out.read_bytes()
    hdr = np.frombuffer(raw[:32], PC2_HEADER)[0]
    times = perf.tracks.frame_times()
    assert hdr["points"] == foreign.model.n_vertices and hdr["samples"] == times.size
    P = np.frombuffer(raw[32:], "<f4").reshape(times.size, foreign.model.n_vertices, 3)
    # the same frames the library clones, in metres
    frames = np.stack([perf.evaluate_at(float(t)) for t in times])
    want = clone_animation(frames, perf, foreign.model) * foreign.model.metadata.metres_per_unit
    np.testing.assert_allclose(P, want, atol=1e-5 * np.abs(want).max())
    # and it follows the true performance on that face
    names = ["jawOpen", "mouthSmileLeft"]
    W = np.array([[perf.tracks.evaluate(float(t)).weights[n] for n in names] for t in times])
    assert np.ptp(W[:, 0]) == 1.0  # the take moves
    assert _error(want / foreign.model.metadata.metres_per_unit, foreign, names, W) <= 0.10


def test_clone_command_names_bad_inputs(head, tmp_path, capsys) -> None:
    from workbench.cli import main

    still = workbench.load_sample("head")
    still_path = tmp_path / "still.fwb"
    still.save(still_path)
    assert main(["clone", str(tmp_path / "nope.abc"), str(still_path), "--out", str(tmp_path / "o.pc2")]) == 2
    assert "PERFORMANCE" in capsys.readouterr().err
    assert main(["clone", str(still_path), str(still_path), "--out", str(tmp_path / "o.pc2")]) == 2
    assert "timeline has no keys" in capsys.readouterr().err
    assert not (tmp_path / "o.pc2").exists()
