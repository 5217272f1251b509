"""Regions from motion and the four voluntary ones among them (Bermano et al. 2014, §4.3, after Tena et al.)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

import workbench
from workbench.enhance.motion_regions import motion_regions, voluntary_cores_from_motion
from workbench.enhance.voluntary import face_voluntary_cores
from workbench.geometry.axes import face_axes
from workbench.testing import grid_triangles, grid_vertices


def _quadrant_take(n: int = 20) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A grid whose four quadrants move in four directions (2 frames, different amounts)."""
    V = grid_vertices(n)
    F = grid_triangles(n)
    q = (V[:, 0] >= n / 2).astype(int) + 2 * (V[:, 1] >= n / 2).astype(int)
    dirs = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]])
    amount = 0.5 + 0.02 * V[:, 0]  # not uniform: the cosine, not the size, binds vertices
    frames = np.stack([V + s * amount[:, None] * dirs[q] for s in (0.3, 1.0)])
    return V, F, frames, q


def test_quadrants_moving_differently_are_found_exactly() -> None:
    V, F, frames, q = _quadrant_take()
    mr = motion_regions(V, F, frames, n_regions=4)
    assert mr.labels.min() >= 0 and mr.n_regions == 4
    # one label per quadrant and one quadrant per label (a permutation)
    pairs = set(zip(q.tolist(), mr.labels.tolist(), strict=True))
    assert len(pairs) == 4 and len({a for a, _ in pairs}) == 4 and len({b for _, b in pairs}) == 4
    # labels are numbered by size and do not depend on the order of the frames
    again = motion_regions(V, F, frames[::-1], n_regions=4)
    np.testing.assert_array_equal(np.unique(again.labels, return_counts=True)[1], np.bincount(mr.labels))


def test_still_vertices_and_other_pieces_are_in_no_region() -> None:
    V, F, frames, q = _quadrant_take()
    frames[:, q == 0] = V[q == 0]  # one quadrant still
    mr = motion_regions(V, F, frames, n_regions=3)
    assert np.all(mr.labels[q == 0] == -1) and np.all(mr.labels[q != 0] >= 0)
    # a second, separate moving grid is not clustered: only the largest moving piece is
    V2 = np.concatenate([V, V[:50] + np.array([100.0, 0, 0])])
    F2 = np.concatenate([F, grid_triangles(10, 5) + len(V)])
    fr2 = np.concatenate([frames, frames[:, :50] + np.array([100.0, 0, 1.0])], axis=1)
    mr2 = motion_regions(V2, F2, fr2, n_regions=3)
    assert np.all(mr2.labels[len(V):] == -1)


@pytest.fixture(scope="module")
def head() -> workbench.FaceModel:
    return workbench.load_sample("head", "base")


def test_on_the_sample_the_cores_are_the_brows_and_the_mouth(head: workbench.FaceModel) -> None:
    V = np.asarray(head.vertices, np.float64)
    frames = V + np.stack([np.asarray(s.delta, np.float64) for s in head.shapes])
    axes = face_axes(head)
    mr = motion_regions(V, head.faces, frames)
    # every region is one edge-connected piece
    e = np.concatenate([head.faces[:, [0, 1]], head.faces[:, [1, 2]], head.faces[:, [2, 0]]])
    for r in range(mr.n_regions):
        ids = mr.vertices(r)
        inside = np.isin(e, ids).all(axis=1)
        A = sp.csr_matrix((np.ones(inside.sum()), (e[inside, 0], e[inside, 1])), shape=(len(V), len(V)))
        _, lab = connected_components(A, directed=False)
        assert len(np.unique(lab[ids])) == 1, f"region {r} is in pieces"
    cores = voluntary_cores_from_motion(V, mr, axes)
    assert set(cores) == {"mouth_left", "mouth_right", "brow_left", "brow_right"}
    named = face_voluntary_cores(head)
    P = V @ axes.T
    eyes = [np.flatnonzero(head.component_labels == i) for i, n in enumerate(head.component_names) if n.startswith("eye_")]
    eye_height = max(P[ids, 1].mean() for ids in eyes)
    for name, ids in cores.items():
        side = 1.0 if name.endswith("left") else -1.0
        mouth = np.concatenate([cores["mouth_left"], cores["mouth_right"]])
        assert np.all(side * (P[ids, 0] - np.median(P[mouth, 0])) >= 0), name
        # most of what the shape names call the brow / the lips is in the region found from motion alone
        assert np.isin(named[name], ids).mean() > 0.6, (name, np.isin(named[name], ids).mean())
    assert P[cores["brow_left"], 1].mean() > eye_height > P[cores["mouth_left"], 1].mean()


def test_bad_input_gives_clear_errors() -> None:
    V, F, frames, _ = _quadrant_take(6)
    with pytest.raises(ValueError, match=r"frames must be \(T, 36, 3\)"):
        motion_regions(V, F, frames[:, :10])
    with pytest.raises(ValueError, match="no vertex moves"):
        motion_regions(V, F, np.repeat(V[None], 2, axis=0))
    with pytest.raises(ValueError, match="only 36 connected moving vertices for 13 regions"):
        motion_regions(V, F, frames)
    with pytest.raises(ValueError, match="n_regions must be >= 2"):
        motion_regions(V, F, frames, n_regions=1)
    # the lower half barely moves (above "still", below "active"): no mouth
    V, F, frames, q = _quadrant_take(20)
    frames[:, q < 2] = V[q < 2] + 0.06 * (frames[:, q < 2] - V[q < 2])
    mr = motion_regions(V, F, frames, n_regions=4)
    with pytest.raises(ValueError, match="no moving region in the lower 40 %"):
        voluntary_cores_from_motion(V, mr, np.eye(3))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_on_faces_it_has_not_seen_the_cores_match_what_the_names_say(head: workbench.FaceModel, seed: int) -> None:
    """Foreign faces (remeshed, warped, other proportions, cm, open mouth and eyes, split and renamed shapes)."""
    from workbench.testing.conventions import foreign_face

    face = foreign_face(head, seed=seed).model
    V = np.asarray(face.vertices, np.float64)
    frames = V + np.stack([np.asarray(s.delta, np.float64) for s in face.shapes])
    cores = voluntary_cores_from_motion(V, motion_regions(V, face.faces, frames), face_axes(face))
    named = face_voluntary_cores(face)  # the renamed shapes still say "brow" / "mouth": the reference
    assert set(cores) == set(named)
    for name in named:
        # a brow core may be the inner half of a brow region crossing the midline: less of the named brow
        share = 0.5 if name.startswith("mouth") else 0.3
        assert np.isin(named[name], cores[name]).mean() > share, (name, np.isin(named[name], cores[name]).mean())


def test_the_procedural_database_finds_its_regions_from_motion_by_default(head: workbench.FaceModel) -> None:
    from workbench.enhance.performance import procedural_database

    by_motion = procedural_database(head, n_frames=4).database
    by_names = procedural_database(head, n_frames=4, regions="names").database
    one = procedural_database(head, n_frames=4, regions=False).database
    assert sorted(by_motion.region_names_) == sorted(by_names.region_names_) == sorted(
        ["mouth_left", "mouth_right", "brow_left", "brow_right"])
    assert len(one.region_names_) == 1
    with pytest.raises(ValueError, match="regions must be 'motion', 'names', True or False, got 'eyes'"):
        procedural_database(head, n_frames=4, regions="eyes")
