"""Example-based rig refinement (Li et al. 2010 §3): ``workbench.rigging.refine_rig``.

Ground truth built here: an "actor" whose shapes are the sample head's changed
by a known smooth per-shape field, in two kinds —

* *displacement* actor: each delta scaled (×0.65–1.35) and turned (±0.3 rad)
  by smooth fields over the head, ``D'_i(v) = s_i(v) R_i(v) A_i(v)``;
* *deformation* actor: each shape's triangle frames scaled and turned by such
  fields and the shape rebuilt from them (the actor's skin stretches more or
  less, regionally), with the template's fixed vertices.

Examples are actor poses at known weights (1–3 shapes each), the rough
weights the true ones ± up to 0.3 (Li Fig. 3). The rig starts as the
template (the sample's own shapes). Held-out error: random poses not used as
examples, evaluated at their true weights, relative to the template's error
(1 = no better than the template, 0 = the actor exactly).
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

import workbench
from workbench.geometry.operators import cotangent_laplacian
from workbench.model import FaceModel
from workbench.rigging import RefineResult, refine_rig
from workbench.rigging.gradients import PoissonSolver, TriangleGradients
from workbench.rigging.refine_steps import _box_qp, _exclusive_qp

#: a 16-shape rig with overlapping shapes around one eye, the brows, nose, jaw and mouth
SUBSET = [
    "browDownLeft", "browInnerUp", "browOuterUpLeft", "eyeBlinkLeft", "eyeWideLeft",
    "eyeSquintLeft", "cheekSquintLeft", "noseSneerLeft", "jawOpen", "jawLeft",
    "mouthSmileLeft", "mouthFrownLeft", "mouthPucker", "mouthFunnel", "mouthStretchLeft",
    "mouthUpperUpLeft",
]  # fmt: skip


@pytest.fixture(scope="module")
def head() -> FaceModel:
    return workbench.load_sample("head")


@pytest.fixture(scope="module")
def rig(head: FaceModel) -> FaceModel:
    return _with_shapes(head, SUBSET)


def _with_shapes(model: FaceModel, names: list[str]) -> FaceModel:
    return FaceModel(
        model.vertices,
        model.faces,
        [model.shape(nm) for nm in names],
        polygons=model.polygons,
        component_labels=model.component_labels,
        component_names=model.component_names,
        metadata=model.metadata,
    )


def _rotations(axis: NDArray[np.float64], angle: NDArray[np.float64]) -> NDArray[np.float64]:
    a = axis / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3)[None] + s * K[None] + (1 - c) * (K @ K)[None]


def _field(P: NDArray[np.float64], centre: NDArray[np.float64], wavelength: float, seed: int):
    """A smooth scale field (0.65–1.35) and rotation field (±0.3 rad) at points P, drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    phase = rng.uniform(0, 2 * np.pi, 2)
    axis = rng.normal(size=3)
    x = 2 * np.pi * ((P - centre) @ d) / wavelength
    return 1 + 0.35 * np.sin(x + phase[0]), _rotations(axis, 0.3 * np.cos(x + phase[1]))


def _actor(model: FaceModel, kind: str) -> NDArray[np.float64]:
    """The actor's deltas (k, n, 3): the model's changed by known smooth per-shape fields."""
    V = model.vertices
    A = model.deltas.astype(np.float64)
    centre = V.mean(axis=0)
    wavelength = 0.4 * float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    out = np.empty_like(A)
    if kind == "displacement":
        for i in range(len(A)):
            s, R = _field(V, centre, wavelength, seed=i)
            out[i] = s[:, None] * np.einsum("nij,nj->ni", R, A[i])
        return out
    grads = TriangleGradients(V, model.faces)
    centroids = V[grads.faces].mean(axis=1)
    for i in range(len(A)):
        s, R = _field(centroids, centre, wavelength, seed=i)
        # the same scale at the vertices (the translation of pieces no fixed vertex holds)
        sv, _ = _field(V, centre, wavelength, seed=i)
        frames = s[:, None, None] * np.einsum("tij,tjk->tik", R, grads.frames(A[i]))
        disp = np.linalg.norm(A[i], axis=1)
        out[i] = PoissonSolver(grads, disp > 1e-3 * disp.max()).solve(frames, sv[:, None] * A[i])
    return out


def _poses(k: int, count: int, seed: int) -> NDArray[np.float64]:
    rng = np.random.default_rng(seed)
    W = np.zeros((count, k))
    for j in range(count):
        idx = rng.choice(k, size=rng.integers(1, 4), replace=False)
        W[j, idx] = rng.uniform(0.4, 1.0, idx.size)
    return W


def _rough(W: NDArray[np.float64], x: float, seed: int = 7) -> NDArray[np.float64]:
    """Li Fig. 3: each given weight perturbed by a random value in [-x, x] (kept in [0, 1])."""
    noise = np.random.default_rng(seed).uniform(-x, x, W.shape)
    return np.clip(W + noise * (W > 0), 0.0, 1.0)


def _as_dicts(names: list[str], W: NDArray[np.float64]) -> list[dict[str, float]]:
    return [{names[i]: float(w[i]) for i in np.flatnonzero(w)} for w in W]


def _held_out(
    template: NDArray[np.float64], actor: NDArray[np.float64], refined: NDArray[np.float64]
) -> float:
    """Error on 40 poses not used as examples, relative to the template's."""
    W = _poses(len(actor), 40, seed=99)
    truth = np.einsum("mk,knd->mnd", W, actor)
    err = np.einsum("mk,knd->mnd", W, refined) - truth
    err0 = np.einsum("mk,knd->mnd", W, template) - truth
    return float(np.sqrt((err**2).sum() / (err0**2).sum()))


class _Run:
    def __init__(
        self, rig: FaceModel, actor: NDArray[np.float64], count: int, noise: float, space: str
    ) -> None:
        # nested: the first 2 examples are among the first 6, ...
        W_all = _poses(len(actor), 48, seed=1)
        self.W = W_all[:count]
        self.rough = _rough(self.W, noise)
        examples = rig.vertices[None] + np.einsum("mk,knd->mnd", self.W, actor)
        self.result: RefineResult = refine_rig(
            rig,
            list(examples),
            _as_dicts(rig.shape_names, self.rough),
            space=space,  # type: ignore[arg-type]
        )
        refined = self.result.model.deltas.astype(np.float64)
        self.held_out = _held_out(rig.deltas.astype(np.float64), actor, refined)
        active = self.W > 0
        self.weight_error = float(np.abs(self.result.weights - self.W)[active].mean())
        self.rough_error = float(np.abs(self.rough - self.W)[active].mean())
        self.fit = float(self.result.errors[:, -1].mean() / self.result.initial_errors.mean())


_RUNS: dict[tuple[str, int, str], _Run] = {}


def _run(rig: FaceModel, kind: str, count: int, space: str = "gradient") -> _Run:
    key = (kind, count, space)
    if key not in _RUNS:
        _RUNS[key] = _Run(rig, _actor(rig, kind), count, 0.3, space)
    return _RUNS[key]


# ---------------------------------------------------------------------- identities


def test_examples_made_by_the_rig_leave_it_unchanged(head: FaceModel) -> None:
    """Examples generated exactly by the rig at exact weights: the rig and the weights come back."""
    k = len(head.shapes)
    W = _poses(k, 6, seed=3)
    W[0, 0] = 1.0  # a weight at the slider's end
    examples = head.vertices[None] + np.einsum("mk,knd->mnd", W, head.deltas.astype(np.float64))
    before = head.deltas.copy()
    for weights in (_as_dicts(head.shape_names, W), None):
        res = refine_rig(head, list(examples), weights, iterations=3)
        D = res.model.deltas
        assert np.abs(D - head.deltas).max() <= 1e-5 * np.abs(head.deltas).max()
        np.testing.assert_allclose(res.weights, W, atol=1e-6)
        assert res.errors.shape == (6, 3)
        assert res.errors.max() < 1e-6 * np.abs(head.deltas).max()
    np.testing.assert_array_equal(head.deltas, before)  # the input is not modified
    assert res.model is not head
    assert res.model.shape_names == head.shape_names
    assert res.model.metadata.provenance[-1]["operation"] == "refine_rig"
    np.testing.assert_array_equal(res.model.vertices, head.vertices)


def test_result_fields_schedules_and_progress(rig: FaceModel) -> None:
    W = _poses(len(rig.shapes), 3, seed=5)
    examples = rig.vertices[None] + np.einsum("mk,knd->mnd", W, 1.1 * rig.deltas.astype(np.float64))
    calls: list[tuple[float, str]] = []
    res = refine_rig(
        rig, examples, _as_dicts(rig.shape_names, W), progress=lambda f, m: calls.append((f, m))
    )
    assert isinstance(res, RefineResult)
    assert res.weights.shape == (3, len(rig.shapes)) and res.errors.shape == (3, 10)
    assert res.initial_errors.shape == (3,)
    np.testing.assert_allclose(res.betas[[0, -1]], [0.5, 0.1])
    np.testing.assert_allclose(res.gammas[[0, -1]], [1000.0, 100.0])
    assert np.all(np.diff(res.betas) < 0) and np.all(np.diff(res.gammas) < 0)
    fractions = [f for f, _ in calls]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert any("iteration 10/10" in m for _, m in calls)
    # every example is fitted much better than by the template at the rough weights
    assert np.all(res.errors[:, -1] < 0.3 * res.initial_errors)


# ---------------------------------------------------------------------- ground truth


def test_held_out_error_falls_as_examples_grow(rig: FaceModel) -> None:
    runs = [_run(rig, "displacement", c) for c in (2, 6, 12)]
    held = [r.held_out for r in runs]
    print("held-out error vs examples 2/6/12:", np.round(held, 3))
    assert held[0] > held[1] > held[2]
    assert held[2] < 0.85
    for r in runs:
        # the training poses are reproduced ...
        assert r.fit < 0.25, r.fit
        # ... and the weights move from the rough guesses toward the true ones
        assert r.weight_error < 0.8 * r.rough_error, (r.weight_error, r.rough_error)


@pytest.mark.parametrize("kind", ["displacement", "deformation"])
def test_gradient_space_beats_vertex_space(rig: FaceModel, kind: str) -> None:
    """Li §4 Fig. 4: the same energy, weights, fixed vertices and step B, optimised on vertices instead."""
    grad = _run(rig, kind, 24, "gradient")
    vert = _run(rig, kind, 24, "vertex")
    print(f"{kind}: held-out gradient {grad.held_out:.3f}, vertex {vert.held_out:.3f}")
    assert grad.held_out < vert.held_out


# ---------------------------------------------------------------------- exclusive pairs


def test_exclusive_pairs_are_never_both_active(rig: FaceModel) -> None:
    names = rig.shape_names
    k = len(names)
    W = np.zeros((4, k))
    blink, wide = names.index("eyeBlinkLeft"), names.index("eyeWideLeft")
    W[:, blink] = [0.8, 0.0, 0.5, 0.3]
    W[:, wide] = [0.0, 0.7, 0.0, 0.0]
    W[:, names.index("jawOpen")] = 0.5
    examples = rig.vertices[None] + np.einsum("mk,knd->mnd", W, rig.deltas.astype(np.float64))
    rough = W.copy()
    for c in (blink, wide):  # the guesses have both on in every example
        rough[W[:, c] == 0, c] = 0.3
    free = refine_rig(rig, examples, _as_dicts(names, rough), iterations=2)
    paired = refine_rig(
        rig,
        examples,
        _as_dicts(names, rough),
        iterations=2,
        exclusive=[("eyeBlinkLeft", "eyeWideLeft")],
    )
    assert np.any((free.weights[:, blink] > 0) & (free.weights[:, wide] > 0))
    assert not np.any((paired.weights[:, blink] != 0) & (paired.weights[:, wide] != 0))
    np.testing.assert_allclose(paired.weights[:, [blink, wide]], W[:, [blink, wide]], atol=0.1)


def test_exclusive_qp_is_the_best_branch() -> None:
    """The branch-and-resolve QP equals brute force over which member of each pair is zero."""
    rng = np.random.default_rng(0)
    for _ in range(20):
        k = 6
        M = rng.normal(size=(10, k))
        H = M.T @ M + 0.1 * np.eye(k)
        q = rng.normal(size=k) * 3
        lo, hi = np.zeros(k), np.ones(k)
        pairs = [(0, 1), (2, 3)]
        x = _exclusive_qp(H, q, lo, hi, pairs)
        assert not any(x[a] != 0 and x[b] != 0 for a, b in pairs)
        best = min(
            _box_qp(H, q, lo, hi, np.isin(np.arange(k), [z1, z2], invert=True))[1]
            for z1 in (0, 1)
            for z2 in (2, 3)
        )
        assert 0.5 * x @ H @ x - q @ x <= best + 1e-9


# ---------------------------------------------------------------------- muted shapes and bad input


def test_muted_shape_is_kept_and_weightless(rig: FaceModel) -> None:
    model = _with_shapes(rig, rig.shape_names)
    model.set_shape_mute("jawLeft", True)
    W = _poses(len(rig.shapes), 3, seed=11)
    W[:, rig.shape_names.index("jawLeft")] = 0.0
    examples = model.vertices[None] + np.einsum(
        "mk,knd->mnd", W, 1.2 * model.deltas.astype(np.float64)
    )
    res = refine_rig(model, examples, _as_dicts(model.shape_names, W), iterations=2)
    j = model.shape_names.index("jawLeft")
    np.testing.assert_array_equal(res.model.deltas[j], model.deltas[j])
    assert res.model.shape("jawLeft").mute
    assert np.all(res.weights[:, j] == 0)
    with pytest.raises(ValueError, match=r"weights\[0\]\['jawLeft'\].*muted"):
        refine_rig(model, examples, [{"jawLeft": 0.5}, {}, {}])


def test_bad_input_names_the_argument(rig: FaceModel) -> None:
    n = rig.n_vertices
    good = [rig.vertices.copy(), rig.vertices.copy()]
    with pytest.raises(ValueError, match=rf"examples\[1\]: expected shape \({n}, 3\)"):
        refine_rig(rig, [good[0], good[1][:-1]])
    bad = rig.vertices.copy()
    bad[17, 1] = np.nan
    with pytest.raises(ValueError, match=r"examples\[1\]: NaN/inf coordinate at vertex 17"):
        refine_rig(rig, [good[0], bad])
    with pytest.raises(ValueError, match=r"examples: need at least one"):
        refine_rig(rig, [])
    with pytest.raises(ValueError, match=r"weights\[1\]: unknown shape names \['smirk'\]"):
        refine_rig(rig, good, [{"jawOpen": 0.5}, {"smirk": 1.0}])
    with pytest.raises(ValueError, match=r"weights: 1 entries, expected one per example \(2\)"):
        refine_rig(rig, good, [{"jawOpen": 0.5}])
    with pytest.raises(ValueError, match=r"weights\[0\]\['jawOpen'\]: must be finite"):
        refine_rig(rig, good, [{"jawOpen": float("nan")}, {}])
    with pytest.raises(
        ValueError, match=r"weights: expected one \{shape: value\} mapping per example"
    ):
        refine_rig(rig, good, {"jawOpen": 0.5})  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"iterations must be a positive integer"):
        refine_rig(rig, good, iterations=0)
    with pytest.raises(ValueError, match=r"space must be 'gradient' or 'vertex'"):
        refine_rig(rig, good, space="uv")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"exclusive\[0\]: unknown shape 'smirk'"):
        refine_rig(rig, good, exclusive=[("jawOpen", "smirk")])
    with pytest.raises(ValueError, match=r"beta must be finite and >= 0"):
        refine_rig(rig, good, beta=(0.5, -1.0))
    with pytest.raises(ValueError, match=r"beta must be > 0"):
        refine_rig(rig, good, beta=(0.5, 0.0))
    empty = FaceModel(rig.vertices, rig.faces)
    with pytest.raises(ValueError, match=r"rig has no blendshapes"):
        refine_rig(empty, good)


# ---------------------------------------------------------------------- the gradient operator


def test_gradient_laplacian_is_the_cotangent_laplacian(head: FaceModel) -> None:
    grads = TriangleGradients(head.vertices, head.faces)
    L = cotangent_laplacian(head.vertices, head.faces)
    assert abs(grads.laplacian + L).max() < 1e-9 * abs(L).max()


def test_poisson_rebuilds_a_shape_from_its_frames(head: FaceModel) -> None:
    grads = TriangleGradients(head.vertices, head.faces)
    for name in ("jawOpen", "mouthSmileLeft", "eyeLookUpLeft"):
        D = head.shape(name).delta.astype(np.float64)
        moving = np.linalg.norm(D, axis=1) > 0
        rebuilt = PoissonSolver(grads, moving).solve(grads.frames(D), D)
        assert np.abs(rebuilt - D).max() < 1e-8 * np.abs(D).max()
        assert np.all(rebuilt[~moving] == 0)
