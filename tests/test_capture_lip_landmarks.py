"""FaceMesh's inner-lip landmarks land on their own lip of a closed-mouth rig.

At a closed mouth FaceMesh's upper and lower inner-lip landmarks coincide, and so do the
rig's two lips; the registration's nearest vertex was a coin flip (8 of 18 on the sample head
fell on the wrong lip, and jawOpen read about half of its truth). Hand-worked cases for the
fix on a two-lip strip, and the pairs checked against MediaPipe's own contours.
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pytest

from workbench.capture.facemesh import N_LANDMARKS
from workbench.capture.landmark_registration import INNER_LIP_PAIRS, _part_the_lips


def _strip(gap: float = 0.0):
    """A closed mouth: 5 upper-lip vertices (jaw motion 0) and 5 lower-lip ones (motion 1) on one seam.

    Vertex 2i is the upper lip at x = i, 2i + 1 the lower lip at the same x (``gap`` below).
    """
    x = np.repeat(np.arange(5.0), 2)
    y = np.tile([0.0, -gap], 5)
    V = np.c_[x, y, np.zeros(10)]
    jaw = np.tile([0.0, 1.0], 5)
    return V, jaw


def _landmarks(V, at):
    """Every landmark far away, the inner-lip pairs at the seam points ``at`` (one x per pair)."""
    X = np.full((N_LANDMARKS, 3), 100.0)
    for (up, lo), x in zip(INNER_LIP_PAIRS, at, strict=False):
        X[up] = X[lo] = (x, 0.0, 0.0)
    return X


def test_an_upper_lip_landmark_on_the_lower_lip_moves_to_the_upper_one():
    V, jaw = _strip()
    X = _landmarks(V, [1.0, 3.0])
    ids = np.zeros(N_LANDMARKS, np.intp)
    ids[[lo for _, lo in INNER_LIP_PAIRS]] = 1  # the other pairs on their own lips already
    (u0, l0), (u1, l1) = INNER_LIP_PAIRS[:2]
    ids[[u0, l0]] = 3  # both on the lower lip at x = 1: the coin flip gone wrong
    ids[[u1, l1]] = 6  # both on the upper lip at x = 3
    before = ids.copy()
    _part_the_lips(ids, X, V, np.arange(10), np.eye(3), jaw)
    assert (ids[u0], ids[l0]) == (2, 3) and (ids[u1], ids[l1]) == (6, 7)  # same x, each on its own lip
    others = np.setdiff1d(np.arange(N_LANDMARKS), [u0, l0, u1, l1])
    assert np.array_equal(ids[others], before[others])


def test_pairs_already_on_their_lips_and_skin_without_a_seam_are_left_alone():
    V, jaw = _strip(gap=0.2)
    X = _landmarks(V, [2.0])
    up, lo = INNER_LIP_PAIRS[0]
    ids = np.zeros(N_LANDMARKS, np.intp)
    ids[up], ids[lo] = 4, 5  # right already
    _part_the_lips(ids, X, V, np.arange(10), np.eye(3), jaw)
    assert (ids[up], ids[lo]) == (4, 5)
    # nothing moves with the jaw there: no seam to split at, the nearest vertices stay
    ids[up], ids[lo] = 5, 5
    _part_the_lips(ids, X, V, np.arange(10), np.eye(3), np.zeros(10))
    assert (ids[up], ids[lo]) == (5, 5)


def test_the_pairs_are_mediapipes_inner_lip_contours_corner_to_corner():
    connections = pytest.importorskip("mediapipe.python.solutions.face_mesh_connections")
    edges = {frozenset(e) for e in connections.FACEMESH_LIPS}
    upper = [78, *(u for u, _ in INNER_LIP_PAIRS), 308]
    lower = [78, *(lo for _, lo in INNER_LIP_PAIRS), 308]
    for chain in (upper, lower):
        assert all(frozenset(e) in edges for e in pairwise(chain)), chain
    assert not set(upper[1:-1]) & set(lower[1:-1])
