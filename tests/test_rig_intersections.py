"""Self-intersections in the rig transfer's quality report (issue 16): ``workbench.rigging.intersections``.

Hand-worked meshes first (two crossing triangles, neighbours that only share
a vertex, a flat strip folded through itself, closed surfaces), then the
narrow phase against libigl's triangle-triangle test and both backends
against all pairs, the rest-pose subtraction, the report's fields and rule,
and a transfer whose template shape pushes the lower lip through the upper.
"""

from __future__ import annotations

import logging

import igl
import numpy as np
import pytest
import trimesh
from grid_meshes import grid_triangles

import workbench
from workbench.model import BlendShape, FaceModel, ModelMetadata
from workbench.rigging import RigTransfer, ShapeQuality, TransferReport, transfer_rig_report
from workbench.rigging import intersections as ix
from workbench.rigging import synthetic as syn
from workbench.rigging.intersections import (
    SelfIntersections,
    self_intersecting_triangles,
    triangles_intersect,
)

needs_numba = pytest.mark.skipif(not ix.NUMBA, reason="numba is not installed")
BACKENDS = [pytest.param("numba", marks=needs_numba), "numpy"]


# ------------------------------------------------------------------ meshes


def ribbon(points_xz: np.ndarray, rows: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A strip along a polyline in the xz plane, ``rows`` quads wide along y.

    Returns V, F and the polyline segment (column) of each triangle. Quad
    (segment k, row r) is split along its diagonal from (k, r) to (k + 1, r + 1).
    """
    P = np.asarray(points_xz, float)
    K = len(P)
    y = np.arange(rows + 1, dtype=float)
    V = np.array([[x, yy, z] for (x, z) in P for yy in y])

    def vid(k: int, r: int) -> int:
        return k * (rows + 1) + r

    F, col = [], []
    for k in range(K - 1):
        for r in range(rows):
            F += [[vid(k, r), vid(k + 1, r), vid(k + 1, r + 1)], [vid(k, r), vid(k + 1, r + 1), vid(k, r + 1)]]
            col += [k, k]
    return V, np.array(F), np.array(col)


#: a polyline that runs along z = 0, turns back above itself and comes down through its segment 2
#: (P2-P3, x in 2..3) at x = 2.5: segments 2 and 6 cross, nothing else meets
FOLDED = np.array([[0, 0], [1, 0], [2, 0], [3, 0], [4, 0], [4, 1], [2.5, 1], [2.5, -1]], float)
FLAT = np.stack([np.arange(len(FOLDED), dtype=float), np.zeros(len(FOLDED))], axis=1)


def two_triangles(lift: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A triangle in z = 0 and a vertical one through its interior at (0.5, 0.5) (lifted by ``lift``)."""
    V = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0.5, 0.5, -1], [0.5, 0.5, 1], [1.5, 1.5, 0]], float)
    V[3:, 2] += lift
    return V, np.array([[0, 1, 2], [3, 4, 5]])


def crumpled_grid(n: int, seed: int, amount: float = 0.8) -> tuple[np.ndarray, np.ndarray]:
    """An n x n grid with random jitter big enough that it crosses itself in many places."""
    rng = np.random.default_rng(seed)
    xs, ys = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    V = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1) + rng.normal(scale=amount, size=(n * n, 3))
    return V, grid_triangles(n)


def all_pairs(V: np.ndarray, F: np.ndarray, only: np.ndarray | None = None) -> np.ndarray:
    """The reference: every pair not sharing a vertex, with the vectorised test (small meshes only)."""
    i, j = np.triu_indices(len(F), 1)
    keep = ~(F[i][:, :, None] == F[j][:, None, :]).any((1, 2))
    if only is not None:
        keep &= only[i] | only[j]
    i, j = i[keep], j[keep]
    yes = triangles_intersect(V[F[i]], V[F[j]])
    out = np.zeros(len(F), bool)
    out[i[yes]] = out[j[yes]] = True
    return out


# ------------------------------------------------------------------ hand-worked


@pytest.mark.parametrize("backend", BACKENDS)
def test_two_crossing_triangles_are_both_flagged_and_apart_neither(backend: str) -> None:
    V, F = two_triangles()
    assert self_intersecting_triangles(V, F, backend=backend).tolist() == [True, True]
    V, F = two_triangles(lift=1.01)  # the vertical one now starts 0.01 above the plane
    assert self_intersecting_triangles(V, F, backend=backend).tolist() == [False, False]
    V, F = two_triangles(lift=1.0)  # its lowest vertex rests on the other's interior: touching counts
    assert self_intersecting_triangles(V, F, backend=backend).tolist() == [True, True]


@pytest.mark.parametrize("backend", BACKENDS)
def test_triangles_sharing_a_vertex_are_never_a_pair(backend: str) -> None:
    # a fan of two triangles that share vertex 0 and are otherwise apart
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0.5], [0, -1, 0.5]], float)
    F = np.array([[0, 1, 2], [0, 3, 4]])
    assert not self_intersecting_triangles(V, F, backend=backend).any()
    # the crossing pair of the first test, glued at one vertex: crossing, but neighbours do not count
    V, F = two_triangles()
    F2 = F.copy()
    F2[1, 2] = 0  # the vertical triangle's third corner is now the other's vertex 0
    assert not self_intersecting_triangles(V, F2, backend=backend).any()
    assert triangles_intersect(V[F2[:1]], V[F2[1:]]).all()  # ... though the triangles do cross


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_flat_strip_folded_through_itself_flags_exactly_the_crossing_columns(backend: str) -> None:
    V, F, col = ribbon(FOLDED)
    got = self_intersecting_triangles(V, F, backend=backend)
    want = np.isin(col, [2, 6])  # segment 2 (x 2..3 on z = 0) and segment 6 (x = 2.5, z 1 -> -1)
    assert want.sum() == 12
    np.testing.assert_array_equal(got, want)
    # the same through the rest-pose API: flat at rest, folded by a displacement
    V0, F0, _ = ribbon(FLAT)
    np.testing.assert_array_equal(F0, F)
    si = SelfIntersections(V0, F0, backend=backend)
    assert not si.rest.any()
    np.testing.assert_array_equal(si.new(V - V0), want)
    assert si.count_new(V - V0) == 12 and si.count_new(np.zeros_like(V0)) == 0
    # folded a little less, so segment 6 stops short of the plane: nothing
    short = FOLDED.copy()
    short[7, 1] = 0.05
    V2, _, _ = ribbon(short)
    assert si.count_new(V2 - V0) == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_closed_surfaces_do_not_intersect_themselves(backend: str) -> None:
    tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    tet_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    assert not self_intersecting_triangles(tet, tet_F, backend=backend).any()
    sphere = trimesh.creation.icosphere(subdivisions=3)
    assert not self_intersecting_triangles(sphere.vertices, sphere.faces, backend=backend).any()
    # and a real face: the sample head's skin at rest
    head = workbench.load_sample("head")
    skin = head.component_labels == 0
    F = head.faces[skin[head.faces].all(1)]
    assert not self_intersecting_triangles(head.vertices, F, backend=backend).any()
    # two spheres that overlap: every triangle on the circle where they cross, and only those
    other = sphere.vertices + np.array([1.0, 0, 0])
    V = np.concatenate([sphere.vertices, other])
    F2 = np.concatenate([sphere.faces, sphere.faces + len(sphere.vertices)])
    got = self_intersecting_triangles(V, F2, backend=backend)
    d0 = np.linalg.norm(V[F2] - [0, 0, 0], axis=2)  # per corner: inside the first sphere?
    d1 = np.linalg.norm(V[F2] - [1, 0, 0], axis=2)
    straddle = np.where(np.arange(len(F2))[:, None] < len(sphere.faces), d1, d0)
    assert got.sum() > 0
    # (the other mesh lies within 0.005 inside its sphere: edges of ~0.15 on a unit sphere)
    assert got[(straddle.min(1) < 0.99) & (straddle.max(1) > 1.0)].all()  # a corner on each side: crosses
    assert not got[straddle.min(1) > 1.01].any()  # wholly outside the other sphere: no


# ------------------------------------------------------------------ against references


def test_the_narrow_phase_agrees_with_libigl() -> None:
    rng = np.random.default_rng(3)
    p = 3000
    A = rng.normal(size=(p, 3, 3))
    B = rng.normal(size=(p, 3, 3)) + rng.normal(scale=0.8, size=(p, 1, 3))
    flat = np.zeros((p, 3))
    flat[:, 2] = 1.0
    cases = [(A, B)]
    A2, B2 = A.copy(), B.copy()
    A2[..., 2] = 0.0  # coplanar pairs: the in-plane axes decide
    B2[..., 2] = 0.0
    cases.append((A2, B2))
    for X, Y in cases:
        ours = triangles_intersect(X, Y)
        theirs = np.array([igl.tri_tri_overlap_test_3d(X[k, :1], X[k, 1:2], X[k, 2:], Y[k, :1], Y[k, 1:2], Y[k, 2:])
                           for k in range(p)])
        assert 0.1 < ours.mean() < 0.9
        np.testing.assert_array_equal(ours, theirs)


@pytest.mark.parametrize("backend", BACKENDS)
def test_pairs_far_apart_are_found_by_the_grid_as_by_the_pair_test(backend: str) -> None:
    # 600 random pairs (every other one coplanar), each at its own place on a line far from the others
    rng = np.random.default_rng(5)
    p = 600
    A = rng.normal(size=(p, 3, 3))
    B = rng.normal(size=(p, 3, 3)) + rng.normal(scale=0.8, size=(p, 1, 3))
    A[::2, :, 2] = B[::2, :, 2] = 0.0
    shift = (np.arange(p) * 50.0)[:, None, None] * np.array([1.0, 0.3, 0.0])
    V = np.concatenate([A + shift, B + shift]).reshape(-1, 3)
    F = np.arange(2 * p * 3).reshape(2 * p, 3)
    got = self_intersecting_triangles(V, F, backend=backend)
    want = triangles_intersect(A, B)
    np.testing.assert_array_equal(got[:p], want)
    np.testing.assert_array_equal(got[p:], want)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("backend", BACKENDS)
def test_both_backends_find_what_all_pairs_find(backend: str, seed: int) -> None:
    V, F = crumpled_grid(14, seed)
    want = all_pairs(V, F)
    assert 0.2 < want.mean() < 0.95
    np.testing.assert_array_equal(self_intersecting_triangles(V, F, backend=backend), want)
    # a few triangles only: a triangle outside them counts when it meets one of them
    only = np.zeros(len(F), bool)
    only[np.random.default_rng(seed).choice(len(F), 40, replace=False)] = True
    np.testing.assert_array_equal(self_intersecting_triangles(V, F, only=only, backend=backend),
                                  all_pairs(V, F, only))
    np.testing.assert_array_equal(self_intersecting_triangles(V, F, only=np.flatnonzero(only), backend=backend),
                                  all_pairs(V, F, only))
    # big and small triangles together (the grid's cell grows for big ones)
    V2 = V.copy()
    V2[:14, 1] += 20.0  # the first row of vertices pulled across the grid: long triangles over small ones
    np.testing.assert_array_equal(self_intersecting_triangles(V2, F, backend=backend), all_pairs(V2, F))


# ------------------------------------------------------------------ the rest pose


@pytest.mark.parametrize("backend", BACKENDS)
def test_only_intersections_new_since_the_rest_pose_count(backend: str) -> None:
    # a crossing pair at rest (like closed lips touching) beside the flat strip
    Vs, Fs, col = ribbon(FLAT)
    Vx, Fx = two_triangles()
    Vx = Vx + np.array([0, 10.0, 0])
    V0 = np.concatenate([Vs, Vx])
    F = np.concatenate([Fs, Fx + len(Vs)])
    si = SelfIntersections(V0, F, backend=backend)
    assert si.rest.tolist() == [False] * len(Fs) + [True, True]
    Vf, _, _ = ribbon(FOLDED)
    D = np.zeros_like(V0)
    D[: len(Vs)] = Vf - Vs  # fold the strip
    D[len(Vs):] = [0.3, -0.2, 0.1]  # and move the crossing pair rigidly: still crossing, not new
    new = si.new(D)
    np.testing.assert_array_equal(new[: len(Fs)], np.isin(col, [2, 6]))
    assert not new[len(Fs):].any()
    # the same as two full checks
    full = self_intersecting_triangles(V0 + D, F, backend=backend) & ~self_intersecting_triangles(V0, F, backend=backend)
    np.testing.assert_array_equal(new, full)


@pytest.mark.parametrize("backend", BACKENDS)
def test_testing_only_the_moving_triangles_is_the_same_as_two_full_checks(backend: str) -> None:
    V0, F = crumpled_grid(16, 7, amount=0.45)  # some crossings at rest
    si = SelfIntersections(V0, F, backend=backend)
    assert 0 < si.rest.sum() < len(F)
    rng = np.random.default_rng(8)
    for _ in range(4):
        D = np.zeros_like(V0)
        moving = rng.choice(len(V0), 40, replace=False)  # a few vertices move, the rest keep still
        D[moving] = rng.normal(scale=0.8, size=(40, 3))
        full = all_pairs(V0 + D, F) & ~all_pairs(V0, F)
        assert full.any()
        np.testing.assert_array_equal(si.new(D), full)
    # every vertex moving a little, from well under the clearances to about them: only the triangles moving
    # by half their clearance are tested, and the answer is still that of the full checks
    if backend == "numba":
        assert (si.clearance[~si.rest] > 0).all() and (si.clearance[si.rest] == 0).all()
    found = 0
    for scale in (0.02, 0.05, 0.1, 0.2):
        D = rng.normal(scale=scale, size=V0.shape)
        full = all_pairs(V0 + D, F) & ~all_pairs(V0, F)
        np.testing.assert_array_equal(si.new(D), full, err_msg=f"scale {scale}")
        found += full.sum()
    assert found > 0
    # a vertex moving by less than tol counts as still
    D = np.zeros_like(V0)
    D[5] = 0.5 * si.tol
    assert si.count_new(D) == 0


@needs_numba
def test_the_clearance_is_a_lower_bound_on_the_distance() -> None:
    V0, F = crumpled_grid(12, 11, amount=0.3)
    si = SelfIntersections(V0, F)
    i, j = np.triu_indices(len(F), 1)
    keep = ~(F[i][:, :, None] == F[j][:, None, :]).any((1, 2))
    i, j = i[keep], j[keep]
    # the distance between two triangles: the closest of their corners to the other triangle and of their edges
    pts = np.linspace(0, 1, 9)
    w = np.array([(a, b, 1 - a - b) for a in pts for b in pts if a + b <= 1 + 1e-12])
    Pa = np.einsum("sk,tkc->tsc", w, V0[F])  # sample points over each triangle
    dist = np.full(len(F), np.inf)
    for a, b in zip(i, j, strict=True):
        d = np.sqrt(((Pa[a][:, None] - Pa[b][None]) ** 2).sum(-1)).min()  # >= the true distance
        dist[a], dist[b] = min(dist[a], d), min(dist[b], d)
    assert (si.clearance <= dist + 1e-12).all()
    # and not far below it where the triangles are apart (the samples are 1/8 of an edge apart)
    assert np.median(si.clearance[~si.rest] / np.minimum(dist[~si.rest], si.clearance.max())) > 0.3


def test_argument_errors() -> None:
    V, F = two_triangles()
    with pytest.raises(ValueError, match=r"V must be \(n, 3\)"):
        self_intersecting_triangles(V[:, :2], F)
    with pytest.raises(ValueError, match=r"F must be \(m, 3\)"):
        self_intersecting_triangles(V, F[:, :2])
    with pytest.raises(ValueError, match="outside"):
        self_intersecting_triangles(V, F + 10)
    with pytest.raises(ValueError, match="backend"):
        self_intersecting_triangles(V, F, backend="gpu")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="only: a mask must be"):
        self_intersecting_triangles(V, F, only=np.ones(3, bool))
    with pytest.raises(ValueError, match=r"D must be \(6, 3\)"):
        SelfIntersections(V, F).new(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="finite"):
        self_intersecting_triangles(np.where(V == 2, np.nan, V), F)


# ------------------------------------------------------------------ the report


def quality(name: str = "s", **kw) -> ShapeQuality:
    base = dict(name=name, max_stretch=1.2, median_stretch=1.01, flipped=0, source_max_stretch=1.2, source_flipped=0,
                moved=10)
    return ShapeQuality(**(base | kw))


def test_the_flagging_rule_allows_for_the_meshes_densities() -> None:
    assert quality().concerns() == ()
    assert quality(intersecting=3).concerns() == ("self-intersecting triangles 3 (template 0)",)
    assert quality(flipped=1).concerns() == ("flipped triangles 1 (template 0)",)
    # a target 4x as dense: flips (areas) scale by 4, crossings (curves) by 2; then the 2x slack
    dense = dict(triangles=40000, source_triangles=10000)
    assert quality(intersecting=500, source_intersecting=128, **dense).concerns() == ()
    assert quality(intersecting=520, source_intersecting=128, **dense).concerns() != ()
    assert quality(flipped=300, source_flipped=40, **dense).concerns() == ()
    assert quality(flipped=330, source_flipped=40, **dense).concerns() != ()
    # without the triangle counts (older reports) the counts are compared as they are
    assert quality(intersecting=300, source_intersecting=128).concerns() != ()
    # stretch: 1.3x the template's and above 1.5
    assert quality(max_stretch=2.0, source_max_stretch=1.2).concerns() == ("stretch 2.00 (template 1.20)",)
    assert quality(max_stretch=1.45, source_max_stretch=1.0).concerns() == ()
    assert quality(max_stretch=3.0, source_max_stretch=2.5).concerns() == ()
    report = TransferReport("a", "b", (quality("ok"), quality("bad", intersecting=4), quality("fine")))
    assert [s.name for s in report.flagged] == ["bad"]
    text = report.summary()
    assert "new self-intersections at weight 1: 1 shapes, 4 triangles (template: 0 shapes, 0 triangles)" in text
    assert "bad: self-intersecting triangles 4 (template 0)" in text


def test_reports_saved_before_the_intersections_load() -> None:
    report = TransferReport("a", "b", (quality("x", intersecting=2, source_intersecting=1, triangles=9, source_triangles=8),))
    d = report.to_json()
    assert TransferReport.from_json(d) == report
    for s in d["shapes"]:
        for k in ("intersecting", "source_intersecting", "triangles", "source_triangles"):
            del s[k]
        s["a key from a later version"] = 1.0
    old = TransferReport.from_json(d)
    assert old.shapes[0] == quality("x")
    assert old.shapes[0].intersecting == 0 and old.shapes[0].source_intersecting == 0


# ------------------------------------------------------------------ through the transfer


def lip_rig(head: FaceModel) -> FaceModel:
    """The sample head with three shapes: its jawOpen, browInnerUp, and lipsThrough = -0.6 jawOpen.

    Minus jawOpen shuts the jaw past closed: the lower lip rises through the upper one.
    """
    by = {s.name: s for s in head.shapes}
    shapes = [by["jawOpen"], by["browInnerUp"], BlendShape("lipsThrough", -0.6 * by["jawOpen"].delta)]
    return FaceModel(head.vertices, head.faces, shapes, polygons=head.polygons, component_labels=head.component_labels,
                     component_names=head.component_names, metadata=head.metadata)


def warped_target(head: FaceModel) -> FaceModel:
    """The head re-triangulated (every triangle in four, vertices moved along edges), bumped and in cm."""
    V2, F2, W = syn.split_remesh(head.vertices, head.faces, seed=2)
    lab = head.component_labels[np.asarray(W.argmax(axis=1)).ravel()]
    warp = syn.SmoothWarp(centres=np.array([[0.0, 6.4, 1.3]]), radii=np.array([0.5]),
                          amplitudes=np.array([[0.03, 0.0, 0.05]]), scale=np.array([1.05, 0.97, 1.02]), unit=10.0)
    return FaceModel(warp(V2), F2, component_labels=lab, component_names=head.component_names,
                     metadata=ModelMetadata(name="warped remesh", units="cm"))


@pytest.fixture(scope="module")
def head() -> FaceModel:
    return workbench.load_sample("head")


@pytest.fixture(scope="module")
def lips(head: FaceModel):
    source = lip_rig(head)
    target = warped_target(head)
    return source, target, transfer_rig_report(source, target)


@needs_numba
def test_a_shape_pushing_the_lower_lip_through_the_upper_is_reported(lips) -> None:
    source, target, result = lips
    report = result.report
    through, brow, jaw = report.shape("lipsThrough"), report.shape("browInnerUp"), report.shape("jawOpen")
    print(f"\nlipsThrough: {through.intersecting} target triangles (template {through.source_intersecting})")
    assert through.intersecting > 20 and through.source_intersecting > 5
    assert brow.intersecting == 0 and brow.source_intersecting == 0
    assert jaw.intersecting == 0 and jaw.source_intersecting == 0
    skin = target.component_labels == 0
    assert through.triangles == int(skin[target.faces].all(1).sum())
    assert through.source_triangles == int((source.component_labels[source.faces] == 0).all(1).sum())
    # the same triangles as a check on the rig's own shape, and they are at the mouth
    F = target.faces[skin[target.faces].all(1)]
    D = result.model.shapes[result.model.shape_names.index("lipsThrough")].delta
    hit = SelfIntersections(target.vertices, F).new(D)
    assert hit.sum() == through.intersecting
    P = target.vertices[F[hit]].reshape(-1, 3)
    size = target.vertices.max(0) - target.vertices.min(0)
    # measured: 5.3 x 2.5 x 2.3 cm of an 18 x 27 x 21 cm head
    assert ((P.max(0) - P.min(0)) < [0.4, 0.15, 0.2] * size).all()
    # the summary says so; the saved report keeps it
    assert "new self-intersections at weight 1: 1 shapes" in report.summary()
    assert TransferReport.from_model(result.model).shape("lipsThrough") == through


def test_without_numba_the_transfer_says_it_did_not_check(head: FaceModel, monkeypatch, caplog) -> None:
    source = lip_rig(head)
    monkeypatch.setattr(ix, "NUMBA", False)
    target = FaceModel(head.vertices, head.faces, component_labels=head.component_labels,
                       component_names=head.component_names, metadata=ModelMetadata(name="same", units="dm"))
    with caplog.at_level(logging.WARNING):
        result = RigTransfer(source, target).run()
    assert "self-intersections not checked" in caplog.text
    assert all(s.intersecting == 0 and s.source_intersecting == 0 for s in result.report.shapes)
    assert any("self-intersections not checked" in w for w in result.report.warnings)
