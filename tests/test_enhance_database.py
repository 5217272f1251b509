"""PerformanceDatabase (Bermano et al. 2014, §4): frequency separation, detail encoding, patches, files.

Ground truth is generated: spheres with known curvature and bumps, and the
procedural wrinkled poses of the sample head (``WrinkleSculptor``) whose smooth
blends are known exactly.
"""

from __future__ import annotations

from pathlib import Path

import igl
import numpy as np
import pytest
import trimesh
from scipy.sparse.csgraph import connected_components

import workbench
from workbench.enhance.database import DatabaseError, PerformanceDatabase
from workbench.enhance.frequency import CurvatureFlowFilter
from workbench.enhance.gradients import deformation_gradients, rigid_align
from workbench.enhance.matching import simplex_lsq
from workbench.enhance.patches import face_patches, grow_patches
from workbench.enhance.polar import from_polar
from workbench.enhance.voluntary import voluntary_region_weights
from workbench.methods.wrinkles.examples import EXAMPLE_POSES, WrinkleSculptor


def _sphere(radius: float, subdivisions: int = 5) -> tuple[np.ndarray, np.ndarray]:
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(s.vertices, np.float64), np.asarray(s.faces, np.int64)


def _bumpy(V: np.ndarray, radius: float, amplitude: float, wavelength: float) -> np.ndarray:
    k = 2 * np.pi / wavelength
    u = V / np.linalg.norm(V, axis=1, keepdims=True)
    bump = amplitude * np.sin(k * V[:, 0]) * np.sin(k * V[:, 1]) * np.sin(k * V[:, 2])
    return u * (radius + bump)[:, None]


def _energy(H: np.ndarray, areas: np.ndarray) -> float:
    d = np.sum((np.asarray(H, np.float64) - np.eye(3)) ** 2, axis=(1, 2))
    return float((areas * d).sum() / areas.sum())


def _tilt(H: np.ndarray, areas: np.ndarray) -> float:
    """Area-weighted mean sin² of the angle between detailed and low-frequency triangle normals."""
    h = np.asarray(H, np.float64)
    c = np.cross(h[:, :, 0], h[:, :, 1])
    c /= np.linalg.norm(c, axis=1, keepdims=True)
    return float((areas * (1 - c[:, 2] ** 2)).sum() / areas.sum())


# --------------------------------------------------------------------------- frequency separation


@pytest.mark.parametrize(("radius", "metres_per_unit"), [(100.0, 1e-3), (1.0, 0.1), (0.1, 1.0)])
def test_flow_sign_and_scale_pinned_on_a_smooth_sphere(radius: float, metres_per_unit: float) -> None:
    # A 10 cm sphere in mm, dm or m: (2A_i − λdt L) X = 2A_i X0 shrinks it by 1 / (1 + λdt / (3 r²)),
    # λdt = 125 mm². The printed sign of eq. 1 would grow it; the igl mass instead of 2A_i would
    # shrink 6x more.
    V, F = _sphere(radius)
    flt = CurvatureFlowFilter(125.0, metres_per_unit=metres_per_unit, uniform_steps=0).fit(V, F)
    low = flt.transform(V)
    ratio = np.linalg.norm(low, axis=1) / radius
    r_mm = radius * metres_per_unit * 1e3
    expected = 1.0 / (1.0 + 125.0 / (3 * r_mm**2))
    assert ratio.std() < 1e-3 * (1 - expected)
    assert abs((1 - ratio.mean()) / (1 - expected) - 1) < 0.05
    assert ratio.mean() > 0.99  # ~unchanged


def test_flow_removes_bumps_and_the_detail_band_of_a_smooth_sphere_is_empty() -> None:
    R = 100.0  # mm, a head-sized sphere; edges ~3.4 mm, bumps 1 mm high on a 15 mm wavelength
    V, F = _sphere(R)
    bumpy = _bumpy(V, R, 1.0, 15.0)
    flt = CurvatureFlowFilter(125.0).fit(V, F)
    low = flt.transform(bumpy)
    bumps_before = np.linalg.norm(bumpy, axis=1) - R
    r = np.linalg.norm(low, axis=1)
    bumps_after = r - r.mean()
    # one step with λdt = 125 mm² damps a mode of surface-Laplacian eigenvalue κ by 1 / (1 + λdt κ / 6):
    # ~1/8 for these bumps (κ ≈ 2 (2π/15)² mm⁻²)
    rms = np.sqrt(np.mean(bumps_after**2) / np.mean(bumps_before**2))
    assert 0.05 < rms < 0.2
    assert np.abs(bumps_after).max() < 0.25 * np.abs(bumps_before).max()
    db = PerformanceDatabase.from_frames(V, F, np.stack([V, bumpy]), patch_size=50)
    A = igl.doublearea(V, F)
    smooth, rough = _energy(db.detail_matrices(0), A), _energy(db.detail_matrices(1), A)
    assert smooth < 1e-2  # a uniform ~0.5 % shrink plus the umbrella step's tangential slide
    assert rough > 10 * smooth
    # the surface part of the detail band: tilt of each detailed triangle against its low-frequency one
    tilt_smooth, tilt_rough = _tilt(db.detail_matrices(0), A), _tilt(db.detail_matrices(1), A)
    assert tilt_smooth < 1e-5
    assert tilt_rough > 1e3 * tilt_smooth


def test_constants_are_kept_and_the_filter_commutes_with_affine_maps() -> None:
    V, F = _sphere(100.0, 3)
    X = _bumpy(V, 100.0, 2.0, 30.0)
    flt = CurvatureFlowFilter(125.0).fit(V, F)
    c = np.array([3.0, -1.0, 7.5])
    np.testing.assert_allclose(flt.transform(np.tile(c, (len(V), 1))), np.tile(c, (len(V), 1)), atol=1e-9)
    A = np.array([[1.2, 0.1, 0.0], [0.0, 0.9, 0.3], [0.2, 0.0, 1.1]])
    np.testing.assert_allclose(flt.transform(X @ A.T + c), flt.transform(X) @ A.T + c, atol=1e-8)
    stack = flt.transform(np.stack([X, X @ A.T]))
    np.testing.assert_allclose(stack[0], flt.transform(X), atol=1e-10)


# --------------------------------------------------------------------------- the head database


@pytest.fixture(scope="module")
def head() -> dict[str, object]:
    model = workbench.load_sample("head", "25k")
    sculptor = WrinkleSculptor(model)
    V = np.asarray(model.vertices, np.float64)
    F = np.asarray(model.faces, np.int64)
    poses = list(EXAMPLE_POSES.values())
    frames = np.stack([sculptor.detailed(w) for w in poses]).astype(np.float64)
    smooth = np.stack([sculptor.blend(w) for w in poses])
    db = PerformanceDatabase.from_frames(sculptor.detail_of(V), F, frames, metres_per_unit=0.1)
    return {"model": model, "V": V, "F": F, "frames": frames, "smooth": smooth, "db": db}


def test_low_plus_high_frequency_gradients_reconstruct_the_detailed_frame(head: dict) -> None:
    db: PerformanceDatabase = head["db"]  # type: ignore[assignment]
    frames = head["frames"]
    for i in range(len(frames)):
        low = db.lowpass(frames[i])
        assert np.abs(low - frames[i]).max() > 1e-3  # the split is not trivial
        x = db.reconstruct(db.compose(db.detail_matrices(i), low), frames[i])
        assert np.abs(x - frames[i]).max() < 1e-6  # dm: 0.1 µm
        placed = db.frame(i, low)  # placed at the low frame: a translation per piece only
        shift = placed - x
        _, piece = connected_components(igl.adjacency_matrix(db.faces_), directed=False)
        for p in np.unique(piece):
            s = shift[piece == p]
            assert np.abs(s - s[0]).max() < 1e-6


def test_detail_of_a_wrinkled_pose_moves_a_smooth_blend_toward_the_truth(head: dict) -> None:
    # §5 with the exact match: the detail of pose i put onto the low band of its smooth blend.
    db: PerformanceDatabase = head["db"]  # type: ignore[assignment]
    frames, smooth = head["frames"], head["smooth"]
    ratios = []
    for i in range(len(frames)):
        wrinkled = np.linalg.norm(frames[i] - smooth[i], axis=1) > 1e-3
        x = db.reconstruct(db.compose(db.detail_matrices(i), db.lowpass(smooth[i])), smooth[i])
        before = np.linalg.norm(smooth[i] - frames[i], axis=1)[wrinkled].mean()
        after = np.linalg.norm(x - frames[i], axis=1)[wrinkled].mean()
        ratios.append(after / before)
    # brows ~7-9x closer; around the mouth (nasolabial fold, lips) 2-2.5x: the deep folds keep a
    # low-frequency part that the smooth blend lacks
    assert max(ratios) < 0.7, ratios
    assert min(ratios) < 0.2, ratios
    assert np.mean(ratios) < 0.4, ratios


def test_detail_and_features_ignore_rigid_motions(head: dict) -> None:
    db: PerformanceDatabase = head["db"]  # type: ignore[assignment]
    frames = head["frames"][:2]
    R = trimesh.transformations.rotation_matrix(0.4, [0.3, 1.0, 0.2])[:3, :3]
    moved = frames @ R.T + np.array([0.5, -2.0, 1.0])
    db2 = PerformanceDatabase.from_frames(db.neutral_, db.faces_, moved, metres_per_unit=0.1)
    np.testing.assert_allclose(db2.detail_, db.detail_[:2], atol=2e-4)
    np.testing.assert_allclose(db2.features_, db.features_[:2], atol=1e-6)


def test_features_are_patch_means_of_low_frequency_gradients(head: dict) -> None:
    db: PerformanceDatabase = head["db"]  # type: ignore[assignment]
    np.testing.assert_allclose(db.encode(db.neutral_low_), np.tile(np.eye(3).ravel(), (db.n_patches_, 1)), atol=1e-9)
    low = db.lowpass(head["frames"][3])
    Rm, t = rigid_align(low, db.neutral_low_)
    T = deformation_gradients(db.neutral_low_, db.faces_, low @ Rm.T + t).reshape(-1, 9)
    A = igl.doublearea(db.neutral_low_, db.faces_)
    p = db.face_patch_ == 7
    np.testing.assert_allclose(db.features_[3, 7], (A[p, None] * T[p]).sum(0) / A[p].sum(), atol=1e-9)
    assert db.features_.shape == (6, db.n_patches_, 9)
    # frames differ from each other in the shape space
    assert np.abs(db.features_[0] - db.features_[3]).max() > 1e-2


def test_patches_cover_every_vertex_once_near_the_size_and_connected(head: dict) -> None:
    V, F = head["V"], head["F"]
    lab = grow_patches(V, F, 100, seed=3)
    assert lab.shape == (len(V),) and lab.min() == 0
    counts = np.bincount(lab)
    assert np.all(counts > 0)
    assert abs(len(V) / len(counts) - 100) < 15
    assert 70 <= np.median(counts) <= 130
    assert counts.max() < 3 * 100
    adj = igl.adjacency_matrix(F).tocsr()
    for p in range(len(counts)):
        ids = np.flatnonzero(lab == p)
        assert connected_components(adj[ids][:, ids], directed=False)[0] == 1, p
    fl = face_patches(F, lab)
    assert np.all((fl == lab[F[:, 0]]) | (fl == lab[F[:, 1]]))


def test_regions_give_the_normal_matrices_of_eq3(head: dict) -> None:
    db0: PerformanceDatabase = head["db"]  # type: ignore[assignment]
    V = head["V"]
    left = np.clip((V[:, 0] - 0.0) / 0.2, 0, 1)  # a soft left half, per vertex
    db = PerformanceDatabase.from_frames(
        db0.neutral_, db0.faces_, head["frames"], regions={"left": left, "right": left[::-1] * 0 + 1 - left},
        metres_per_unit=0.1,
    )
    assert db.region_names_ == ["left", "right"]
    w = db.region_weights_[0].astype(np.float64)
    A = igl.doublearea(db.neutral_low_, db.faces_)
    P = db.n_patches_
    wp = np.bincount(db.face_patch_, A * w, P) / np.bincount(db.face_patch_, A, P)
    Dt = db.features_.reshape(len(head["frames"]), -1).T  # columns are frames, as in the paper
    gram = Dt.T @ np.diag(np.repeat(wp, 9)) @ Dt
    np.testing.assert_allclose(db.region_gram_[0], gram, rtol=1e-10)
    np.testing.assert_allclose(db.region_gram_.sum(0), db0.region_gram_[0], rtol=1e-8)


def test_save_load_round_trip_is_exact(head: dict, tmp_path: Path) -> None:
    db: PerformanceDatabase = head["db"]  # type: ignore[assignment]
    path = db.save(tmp_path / "db.npz")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["db.npz"]  # no temp file left
    with np.load(path, allow_pickle=False) as z:
        assert all(z[k].dtype != object for k in z.files)
    back = PerformanceDatabase.load(path)
    for name in ("neutral_", "faces_", "detail_", "features_", "vertex_patch_", "face_patch_", "region_weights_",
                 "neutral_low_", "region_gram_", "region_patch_weights_"):
        a, b = getattr(db, name), getattr(back, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert back.region_names_ == db.region_names_
    assert (back.patch_size, back.lambda_dt, back.metres_per_unit, back.detail_blend) == (
        db.patch_size, db.lambda_dt, db.metres_per_unit, db.detail_blend)
    low = db.lowpass(head["frames"][1])
    np.testing.assert_array_equal(back.frame(1, low), db.frame(1, low))


def test_load_rejects_other_files(tmp_path: Path) -> None:
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(DatabaseError, match="path"):
        PerformanceDatabase.load(tmp_path / "other.npz")
    with pytest.raises(DatabaseError, match="path"):
        PerformanceDatabase.load(tmp_path / "missing.npz")


def test_a_format_1_file_is_read_as_matrix_blend(head: dict, tmp_path: Path) -> None:
    """Format 1 had no detail_blend (matrices, blended as matrices)."""
    db: PerformanceDatabase = head["db"]  # type: ignore[assignment]
    path = db.save(tmp_path / "db.npz")
    with np.load(path, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    data["format"] = np.array("workbench.enhance.database/1")
    del data["detail_blend"]
    np.savez(tmp_path / "v1.npz", **data)
    old = PerformanceDatabase.load(tmp_path / "v1.npz")
    assert old.detail_blend == "matrix"
    np.testing.assert_array_equal(old.detail_, db.detail_)


def _close_per_matrix(a: np.ndarray, b: np.ndarray, tol: float = 1e-5) -> None:
    """Equal up to float32 storage: each 3x3 matrix within ``tol`` of its own size (at least 1)."""
    err = np.linalg.norm(np.asarray(a, np.float64) - b, axis=(-2, -1))
    size = np.maximum(np.linalg.norm(np.asarray(b, np.float64), axis=(-2, -1)), 1.0)
    assert float((err / size).max()) < tol, float((err / size).max())


def test_switching_the_blend_converts_the_detail_and_back(head: dict, tmp_path: Path) -> None:
    db0: PerformanceDatabase = head["db"]  # type: ignore[assignment]
    db = PerformanceDatabase.from_frames(db0.neutral_, db0.faces_, head["frames"][:2], metres_per_unit=0.1)
    matrices = db.detail_.copy()
    assert db.set_detail_blend("polar") is db and db.detail_.shape == (2, len(db.faces_), 9)
    _close_per_matrix(db.detail_matrices(1), matrices[1])  # float32 parts
    low = db.lowpass(head["frames"][1])
    one_hot = np.eye(2)[[1]]
    _close_per_matrix(db.blend_compose(one_hot, low), db.compose(matrices[1], low))
    back = PerformanceDatabase.load(db.save(tmp_path / "polar.npz"))  # the polar parts are what the file keeps
    assert back.detail_blend == "polar"
    np.testing.assert_array_equal(back.detail_, db.detail_)
    db.set_detail_blend("matrix")
    _close_per_matrix(db.detail_, matrices)


def test_load_rejects_a_damaged_file(head: dict, tmp_path: Path) -> None:
    db: PerformanceDatabase = head["db"]  # type: ignore[assignment]
    path = db.save(tmp_path / "db.npz")
    with np.load(path, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    data["features"] = data["features"][:, :-1]
    np.savez(tmp_path / "bad.npz", **data)
    with pytest.raises(DatabaseError, match="do not fit together"):
        PerformanceDatabase.load(tmp_path / "bad.npz")


# --------------------------------------------------------------------------- bad input


def test_an_unknown_detail_blend_is_named() -> None:
    V, F = _sphere(10.0, 2)
    with pytest.raises(DatabaseError, match="detail_blend must be 'matrix' or 'polar', got 'quaternion'"):
        PerformanceDatabase.from_frames(V, F, np.stack([V, V * 1.01]), detail_blend="quaternion")  # type: ignore[arg-type]


def test_bad_input_gives_clear_errors() -> None:
    V, F = _sphere(10.0, 2)
    ok = np.stack([V, V * 1.01])
    with pytest.raises(DatabaseError, match=r"frames have 10 vertices.*neutral has"):
        PerformanceDatabase.from_frames(V, F, np.zeros((2, 10, 3)))
    with pytest.raises(DatabaseError, match="frames is empty"):
        PerformanceDatabase.from_frames(V, F, np.zeros((0, len(V), 3)))
    bad = ok.copy()
    bad[1, 5, 2] = np.nan
    with pytest.raises(DatabaseError, match=r"frames contains NaN.*frame 1"):
        PerformanceDatabase.from_frames(V, F, bad)
    with pytest.raises(DatabaseError, match="pass frames\\[None\\]"):
        PerformanceDatabase.from_frames(V, F, V)
    with pytest.raises(DatabaseError, match="faces index vertices"):
        PerformanceDatabase.from_frames(V, F + 1, ok)
    with pytest.raises(DatabaseError, match="faces must be integer"):
        PerformanceDatabase.from_frames(V, F.astype(float), ok)
    with pytest.raises(DatabaseError, match="neutral contains NaN"):
        PerformanceDatabase.from_frames(np.where(V == V[0], np.nan, V), F, ok)
    with pytest.raises(DatabaseError, match="patch_size"):
        PerformanceDatabase.from_frames(V, F, ok, patch_size=0)
    with pytest.raises(DatabaseError, match="regions\\['a'\\] must hold one weight per vertex"):
        PerformanceDatabase.from_frames(V, F, ok, regions={"a": np.ones(7)})
    with pytest.raises(DatabaseError, match="regions\\['a'\\] is zero everywhere"):
        PerformanceDatabase.from_frames(V, F, ok, regions={"a": np.zeros(len(V))})
    with pytest.raises(DatabaseError, match="regions is empty"):
        PerformanceDatabase.from_frames(V, F, ok, regions={})


# --------------------------------------------------------------------------- voluntary regions


def test_voluntary_region_weights_are_one_on_the_core_and_fall_off_with_geodesic_distance() -> None:
    R = 100.0
    V, F = _sphere(R, 4)
    north = np.flatnonzero(V[:, 2] > 0.95 * R)
    w = voluntary_region_weights(V, F, {"north": north}, sigma=20.0)["north"]
    assert w.shape == (len(F),) and w.dtype == np.float32
    inside = np.all(np.isin(F, north), axis=1)
    np.testing.assert_array_equal(w[inside], 1.0)
    # the geodesic distance from the cap's rim (polar angle acos 0.95) is R (θ − θ0)
    theta = np.arccos(np.clip(V[F].mean(axis=1)[:, 2] / np.linalg.norm(V[F].mean(axis=1), axis=1), -1, 1))
    d = R * (theta - np.arccos(0.95))
    band = (d > 20) & (d < 100)
    d_edges = 20.0 * np.sqrt(-2 * np.log(w[band].astype(np.float64)))
    assert np.all(d_edges >= 0.97 * d[band])  # paths along edges are never shorter than geodesics
    assert np.all(d_edges <= 1.2 * d[band] + 5.0)  # ... and not much longer
    assert np.median(d_edges / d[band]) < 1.2  # ~15 % on an icosphere
    south = V[F].mean(axis=1)[:, 2] < -0.9 * R
    assert w[south].max() < 1e-10
    with pytest.raises(ValueError, match="sigma"):
        voluntary_region_weights(V, F, {"a": north}, sigma=0.0)
    with pytest.raises(ValueError, match=r"cores\['a'\]"):
        voluntary_region_weights(V, F, {"a": [len(V)]}, sigma=1.0)


def test_progress_is_reported_from_0_to_1() -> None:
    V, F = _sphere(50.0, 2)
    seen: list[tuple[float, str]] = []
    PerformanceDatabase.from_frames(V, F, np.stack([V, V * 1.01, V * 0.99]), patch_size=20, progress=lambda f, m: seen.append((f, m)))
    fr = [f for f, _ in seen]
    assert fr[0] == 0.0 and fr[-1] == 1.0 and fr == sorted(fr)
    assert "3 frames" in seen[-1][1]


def test_float32_frames_are_encoded_like_float64() -> None:
    V, F = _sphere(100.0, 3)
    frames = np.stack([_bumpy(V, 100.0, 1.0, 20.0), _bumpy(V, 100.0, 0.5, 25.0)])
    a = PerformanceDatabase.from_frames(V, F, frames, patch_size=30)
    b = PerformanceDatabase.from_frames(V, F, frames.astype(np.float32), patch_size=30)
    np.testing.assert_allclose(b.features_, a.features_, atol=1e-4)
    np.testing.assert_allclose(b.detail_, a.detail_, atol=1e-3)


# --------------------------------------------------------------------------- matching (eq. 2-3) and blending (eq. 4)


def test_simplex_lsq_matches_a_general_solver_and_recovers_convex_weights() -> None:
    from scipy.optimize import minimize

    rng = np.random.default_rng(4)
    for trial in range(5):
        Dt = rng.normal(size=(40, 7))
        w0 = rng.dirichlet(np.ones(7) * 0.5)
        a = Dt @ w0 + (0.0 if trial == 0 else 0.3) * rng.normal(size=40)
        G, b = Dt.T @ Dt, Dt.T @ a
        w = simplex_lsq(G, b)
        assert np.all(w >= 0) and abs(w.sum() - 1) < 1e-12
        if trial == 0:
            np.testing.assert_allclose(w, w0, atol=1e-5)
        def f(v: np.ndarray, Dt: np.ndarray = Dt, a: np.ndarray = a) -> float:
            return float(np.sum((Dt @ v - a) ** 2))

        ref = minimize(
            f,
            np.full(7, 1 / 7),
            method="SLSQP",
            bounds=[(0, 1)] * 7,
            constraints=[{"type": "eq", "fun": lambda v: v.sum() - 1}],
            options={"ftol": 1e-14, "maxiter": 500},
        )
        assert f(w) <= f(ref.x) + 1e-6 * (1 + f(ref.x))
    with pytest.raises(ValueError, match="G must be"):
        simplex_lsq(np.eye(3), np.ones(2))


def test_match_finds_a_database_frame_from_its_low_frequency_version(head: dict) -> None:
    db: PerformanceDatabase = head["db"]  # type: ignore[assignment]
    R = trimesh.transformations.rotation_matrix(0.3, [0.0, 1.0, 0.1])[:3, :3]
    for i in range(db.n_frames_):
        low = db.lowpass(head["frames"][i]) @ R.T + 0.2  # aligned by Horn before encoding
        w = db.match(low)
        assert w.shape == (1, db.n_frames_)
        assert w[0, i] > 0.99, (i, w.round(3))


@pytest.mark.parametrize("blend", ["matrix", "polar"])
def test_blend_detail_follows_eq4(head: dict, blend: str) -> None:
    db0: PerformanceDatabase = head["db"]  # type: ignore[assignment]
    V = head["V"]
    left = (V[:, 0] > 0).astype(float)
    db = PerformanceDatabase.from_frames(
        db0.neutral_, db0.faces_, head["frames"][:3], regions={"left": left, "right": 1 - left}, metres_per_unit=0.1,
        detail_blend=blend,
    )
    one_hot = np.eye(3)[[0, 0]]
    np.testing.assert_allclose(db.blend_detail(one_hot), db.detail_matrices(0), atol=1e-6)
    W = np.eye(3)[[1, 2]]  # the left region takes frame 1, the right frame 2
    H = db.blend_detail(W)
    om = db.region_weights_.astype(np.float64)
    only_left = (om[0] == 1) & (om[1] == 0)
    mixed = (om[0] > 0) & (om[1] > 0)
    np.testing.assert_allclose(H[only_left], db.detail_matrices(1)[only_left], atol=1e-6)
    assert mixed.any()
    share = om[0, mixed] / om[:, mixed].sum(0)
    if blend == "polar":  # linear in the polar parts (rotation vector, stretch), the paper's shape space
        assert db.detail_.shape[2:] == (9,)
        P1, P2 = db.detail_[1].astype(np.float64), db.detail_[2].astype(np.float64)
        expected = from_polar(share[:, None] * P1[mixed] + (1 - share)[:, None] * P2[mixed])
    else:
        assert db.detail_.shape[2:] == (3, 3)
        H1, H2 = db.detail_matrices(1), db.detail_matrices(2)
        expected = share[:, None, None] * H1[mixed] + (1 - share)[:, None, None] * H2[mixed]
    np.testing.assert_allclose(H[mixed], expected, atol=1e-6)
    # the fused kernel gives the same target Jacobians
    low = db.lowpass(head["frames"][0])
    np.testing.assert_allclose(db.blend_compose(W, low), db.compose(H, low), rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="weights must be"):
        db.blend_detail(np.ones((1, 3)))
