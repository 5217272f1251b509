"""Example-based refinement of a blendshape rig (Li, Weise & Pauly 2010, §3).

Paper: "Example-Based Facial Rigging" (``shared/papers/li2010-example-based-facial-rigging.md``).
Given a rig on the actor's neutral ``B0`` whose shapes ``A_i`` are the
template's (carried over by deformation transfer, :func:`workbench.rigging.transfer_rig`),
``m`` example poses ``S_j`` in the rig's topology and rough weights ``α*_j``, alternate

**A — blendshapes in gradient space** (weights fixed). Per triangle, with the
edge frames ``M(·)`` of :mod:`workbench.rigging.gradients` (the normal column
dropped, Li §3 after Botsch et al. 2006), minimise over the shapes' frames ``X_i``

    E_A = Σ_j |M(S_j) - M(B0) - Σ_i α_ij X_i|² + β Σ_i w_i |X_i - M(A_i)|²
    w_i = ((1 + |M_i^A|) / (κ + |M_i^A|))^θ,  κ = 0.1, θ = 2

a (k × k) system per triangle, all triangles in one batched solve. The rig's
neutral is the actor's, so the paper's ``M_i^{A*} = G_{A0→A0+A_i} M_0^B - M_0^B``
is the frame of ``A_i`` itself. ``|M_i^A|`` is read in millimetres on the
paper's 11k-vertex template (the template shape's strain times the rest frame
size this face has at 11k vertices, :func:`triangle_weights`), so ``w_i``
does not depend on this mesh's units or resolution. Each shape is then rebuilt
from its frames by a Poisson solve (factored once per shape with CHOLMOD)
under the paper's drift constraint: vertices the template shape does not move
stay fixed, and a triangle none of whose vertices move is no unknown of that
shape. A piece no fixed vertex holds (an eyeball, the lower teeth moved whole)
gets its mean displacement, which gradients cannot see, from the same blend
solve on the pieces' mean displacements.

**B — weights** (shapes fixed). Per example, the bounded quadratic program

    E_B = c Σ_v |S_j(v) - B0(v) - Σ_i α_ij B_i(v)|² + γ Σ_i (α_ij - α*_ij)²,
    slider_min_i ≤ α_ij ≤ slider_max_i

solved exactly as a k × k bounded least-squares problem
(``scipy.optimize.lsq_linear(method="bvls")`` on the Cholesky factor). ``c``
measures distances in centimetres and the vertex sum per 11,000 vertices; at
that scale γ = 1000 → 100 is of the order of a shape's data term, so rough
weights are corrected without the scale of a shape drifting into its weight
(the paper states no unit for E_B; see ``tests/test_rig_refine.py``).
Mutually exclusive pairs (``α_a α_b = 0``, Li §3) are hard constraints: when
both are non-zero the QP is re-solved with either one held at zero and the
lower energy kept.

Schedules as the paper's §4: β from 0.5 to 0.1 and γ from 1000 to 100,
geometric over the iterations (10 by default). ``space="vertex"`` runs the
paper's ablation (Fig. 4) instead: step A on vertex displacements with the
same weights (area-averaged onto the vertices), the same fixed vertices and
the same step B.

Hand-written because the method is the paper's; the numerics are numpy's
batched solves, CHOLMOD / SuperLU and scipy's BVLS.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.core.families import families, weight_products
from workbench.core.shapes import BlendShape
from workbench.rigging.gradients import TriangleGradients
from workbench.rigging.refine_steps import (
    REFERENCE_VERTICES,
    GradientStep,
    VertexStep,
    rms_errors,
    solve_weights,
    triangle_weights,
)

if TYPE_CHECKING:
    from workbench.model import FaceModel

__all__ = ["RefineResult", "refine_rig"]

Space = Literal["gradient", "vertex"]
Progress = Callable[[float, str], None]

#: the paper gives lengths only in Fig. 6 (E_fit in mm): w_i's frame norms are taken in mm ...
_FRAME_UNIT = 1e-3
#: ... and E_B's vertex distances in cm, where the schedule's γ (1000 → 100) is of the order of a
#: shape's data term, so rough weights are corrected without drifting (measured in tests/test_rig_refine.py)
_FIT_UNIT = 1e-2
#: a vertex is "stationary" in a template shape below this fraction of the shape's largest motion
_STATIONARY = 1e-3


@dataclass(frozen=True, eq=False)
class RefineResult:
    """What :func:`refine_rig` returns.

    Attributes
    ----------
    model : FaceModel
        The refined rig: same neutral, topology, names, slider ranges and
        edits as the input; refined deltas (vertex masks baked in).
    weights : (m, k) float64
        Estimated weights of every example, columns in ``model.shape_names``
        order (muted and derived shapes are 0).
    errors : (m, iterations) float64
        RMS vertex distance between each example and the rig at its weights
        after each iteration, in the model's units.
    initial_errors : (m,) float64
        The same for the input rig at the (clipped) rough weights.
    shape_names : tuple of str
    betas, gammas : (iterations,) float64
        The schedules used.
    space : {"gradient", "vertex"}
    """

    model: FaceModel
    weights: NDArray[np.float64]
    errors: NDArray[np.float64]
    initial_errors: NDArray[np.float64]
    shape_names: tuple[str, ...]
    betas: NDArray[np.float64]
    gammas: NDArray[np.float64]
    space: str


def refine_rig(
    rig: FaceModel,
    examples: Sequence[ArrayLike] | ArrayLike,
    weights: Sequence[Mapping[str, float]] | None = None,
    *,
    iterations: int = 10,
    progress: Progress | None = None,
    exclusive: Sequence[tuple[str, str]] = (),
    beta: tuple[float, float] = (0.5, 0.1),
    gamma: tuple[float, float] = (1000.0, 100.0),
    kappa: float = 0.1,
    theta: float = 2.0,
    space: Space = "gradient",
) -> RefineResult:
    """Refine a rig's blendshapes (and the examples' weights) toward example poses.

    Parameters
    ----------
    rig : FaceModel
        The rig to refine (the actor's neutral with the template's shapes).
        Not modified. Vertices a shape does not move stay fixed in it; muted
        and derived (corrective) shapes are kept as they are.
    examples : sequence of (n, 3) arrays
        Example poses in the rig's topology and units.
    weights : sequence of {shape: value}, optional
        One rough weight guess per example (missing shapes are 0; values are
        clipped to each slider's range). Default: a bounded least-squares fit
        of the input rig to each example.
    iterations : int, default 10
        Alternations of step A (shapes) and step B (weights).
    progress : callable, optional
        ``progress(fraction, message)`` after the set-up and each step.
    exclusive : sequence of (name, name)
        Mutually exclusive pairs: in no example may both be non-zero.
    beta, gamma : (first, last)
        Schedules of the shape regularisation β (> 0) and the weight prior γ
        (>= 0), geometric from first to last over the iterations.
    kappa, theta : float
        Regularisation weights ``w_i = ((1 + g) / (κ + g))^θ``.
    space : {"gradient", "vertex"}
        ``"gradient"`` is the paper's method; ``"vertex"`` its vertex-space ablation.

    Returns
    -------
    RefineResult

    Raises
    ------
    ValueError
        Naming the argument: an example of the wrong shape or with NaN/inf,
        unknown or non-finite weights, a bad pair, schedule or option.
    """
    report: Progress = progress if progress is not None else (lambda f, m: None)
    if (
        not isinstance(iterations, int | np.integer)
        or isinstance(iterations, bool)
        or iterations < 1
    ):
        raise ValueError(f"iterations must be a positive integer, got {iterations!r}")
    if space not in ("gradient", "vertex"):
        raise ValueError(f"space must be 'gradient' or 'vertex', got {space!r}")
    betas = _schedule("beta", beta, int(iterations), positive=True)
    gammas = _schedule("gamma", gamma, int(iterations))
    for name, v in (("kappa", kappa), ("theta", theta)):
        if not (math.isfinite(float(v)) and float(v) > 0):
            raise ValueError(f"{name} must be a positive number, got {v!r}")

    shapes = rig.shapes
    k = len(shapes)
    if k == 0:
        raise ValueError("rig has no blendshapes to refine")
    n = rig.n_vertices
    names = tuple(s.name for s in shapes)
    S = _check_examples(examples, n)
    m = S.shape[0]
    B0 = np.asarray(rig.vertices, dtype=np.float64)
    residual = S - B0[None]  # (m, n, 3)

    derived = set(weight_products(_slot_values(rig)))
    opt = np.array(
        [i for i, s in enumerate(shapes) if not s.mute and s.name not in derived], np.int64
    )
    if opt.size == 0:
        raise ValueError("rig has no blendshape to refine (every shape is muted or derived)")
    lo = np.array([shapes[i].slider_min for i in opt])
    hi = np.array([shapes[i].slider_max for i in opt])
    A = np.asarray(rig.effective_deltas, dtype=np.float64)[opt]  # (ko, n, 3) template shapes
    ko = opt.size
    pairs = _check_pairs(exclusive, names, opt, lo, hi)
    # E_B's vertex sum in cm², rescaled to the paper's 11k vertices (see _FIT_UNIT)
    scale = (rig.metadata.metres_per_unit / _FIT_UNIT) ** 2 * REFERENCE_VERTICES / n

    # stationary vertices of each template shape (Li §3: they stay fixed)
    disp = np.linalg.norm(A, axis=2)  # (ko, n)
    moving = disp > _STATIONARY * disp.max(axis=1, keepdims=True)

    if weights is None:
        report(0.0, "initial weights: bounded least squares on the rig")
        alpha_star = solve_weights(A, residual, scale, np.zeros((m, ko)), 0.0, lo, hi, pairs)
    else:
        alpha_star = np.clip(_check_weights(weights, m, names, opt, derived), lo, hi)

    report(0.02, "set-up: frames, regularisation weights, factorisations")
    grads = TriangleGradients(B0, rig.faces)
    w = triangle_weights(grads, A, rig.metadata.metres_per_unit / _FRAME_UNIT, kappa, theta)
    step_a: GradientStep | VertexStep = (
        GradientStep(grads, A, residual, moving, w, report)
        if space == "gradient"
        else VertexStep(grads, A, residual, moving, w)
    )
    initial_errors = rms_errors(residual, A, alpha_star)

    alpha = alpha_star.copy()
    B = A
    errors = np.empty((m, int(iterations)))
    for it in range(int(iterations)):
        frac = 0.1 + 0.9 * it / iterations
        report(frac, f"iteration {it + 1}/{iterations}: blendshapes (β = {betas[it]:.3g})")
        B = step_a.solve(alpha, float(betas[it]))
        report(
            frac + 0.6 / iterations,
            f"iteration {it + 1}/{iterations}: weights (γ = {gammas[it]:.3g})",
        )
        alpha = solve_weights(B, residual, scale, alpha_star, float(gammas[it]), lo, hi, pairs)
        errors[:, it] = rms_errors(residual, B, alpha)
    report(1.0, "done")

    full = np.zeros((m, k))
    full[:, opt] = alpha
    model = _build_model(rig, opt, B, space, m, int(iterations))
    return RefineResult(
        model=model,
        weights=full,
        errors=errors,
        initial_errors=initial_errors,
        shape_names=names,
        betas=betas,
        gammas=gammas,
        space=space,
    )


# ---------------------------------------------------------------------- input checks and output


def _schedule(
    name: str, value: tuple[float, float], iterations: int, *, positive: bool = False
) -> NDArray[np.float64]:
    """``iterations`` values from ``first`` to ``last``, geometric (linear when one is 0)."""
    try:
        first, last = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (first, last) of numbers, got {value!r}") from None
    if not (math.isfinite(first) and math.isfinite(last)) or min(first, last) < 0:
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    if positive and min(first, last) <= 0:
        raise ValueError(f"{name} must be > 0 (the shapes need their prior), got {value!r}")
    if iterations == 1 or first == last:
        return np.full(iterations, first)
    t = np.arange(iterations) / (iterations - 1)
    if first > 0 and last > 0:
        return np.asarray(first * (last / first) ** t)
    return np.asarray(first + (last - first) * t)


def _check_examples(examples: Any, n: int) -> NDArray[np.float64]:
    if isinstance(examples, np.ndarray):
        if examples.ndim != 3:
            raise ValueError(
                f"examples: expected a sequence of (n, 3) arrays, got an array of shape {examples.shape}"
            )
        items: list[Any] = list(examples)
    else:
        try:
            items = list(examples)
        except TypeError:
            raise ValueError(
                f"examples: expected a sequence of (n, 3) arrays, got {type(examples).__name__}"
            ) from None
    if not items:
        raise ValueError("examples: need at least one example pose")
    out = np.empty((len(items), n, 3))
    for j, e in enumerate(items):
        try:
            a = np.asarray(e, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"examples[{j}]: not a numeric (n, 3) array") from None
        if a.shape != (n, 3):
            raise ValueError(
                f"examples[{j}]: expected shape ({n}, 3) (the rig's vertices), got {a.shape}"
            )
        if not np.isfinite(a).all():
            row = int(np.flatnonzero(~np.isfinite(a).all(axis=1))[0])
            raise ValueError(f"examples[{j}]: NaN/inf coordinate at vertex {row}")
        out[j] = a
    return out


def _check_weights(
    weights: Any, m: int, names: tuple[str, ...], opt: NDArray[np.int64], derived: set[str]
) -> NDArray[np.float64]:
    if isinstance(weights, Mapping) or not isinstance(weights, Sequence):
        raise ValueError(
            f"weights: expected one {{shape: value}} mapping per example, got {type(weights).__name__}"
        )
    if len(weights) != m:
        raise ValueError(f"weights: {len(weights)} entries, expected one per example ({m})")
    col = {names[i]: c for c, i in enumerate(opt)}
    out = np.zeros((m, opt.size))
    for j, wj in enumerate(weights):
        if not isinstance(wj, Mapping):
            raise ValueError(
                f"weights[{j}]: expected a {{shape: value}} mapping, got {type(wj).__name__}"
            )
        unknown = sorted(str(k) for k in wj if k not in names)
        if unknown:
            raise ValueError(
                f"weights[{j}]: unknown shape names {unknown}; the rig has e.g. {list(names[:5])}"
            )
        for key, value in wj.items():
            try:
                v = float(value)
            except (TypeError, ValueError):
                raise ValueError(
                    f"weights[{j}][{key!r}]: expected a number, got {value!r}"
                ) from None
            if not math.isfinite(v):
                raise ValueError(f"weights[{j}][{key!r}]: must be finite, got {value!r}")
            if key not in col:
                if v != 0.0:
                    why = "derived from other weights" if key in derived else "muted"
                    raise ValueError(
                        f"weights[{j}][{key!r}]: the shape is {why} and cannot be refined; give 0 or leave it out"
                    )
                continue
            out[j, col[key]] = v
    return out


def _check_pairs(
    exclusive: Any,
    names: tuple[str, ...],
    opt: NDArray[np.int64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
) -> list[tuple[int, int]]:
    col = {names[i]: c for c, i in enumerate(opt)}
    pairs: list[tuple[int, int]] = []
    for p, pair in enumerate(exclusive):
        try:
            a, b = pair
        except (TypeError, ValueError):
            raise ValueError(
                f"exclusive[{p}]: expected a pair of shape names, got {pair!r}"
            ) from None
        for nm in (a, b):
            if nm not in col:
                what = "unknown" if nm not in names else "muted or derived"
                raise ValueError(f"exclusive[{p}]: {what} shape {nm!r}")
        if a == b:
            raise ValueError(f"exclusive[{p}]: a shape cannot exclude itself ({a!r})")
        ia, ib = col[a], col[b]
        for i, nm in ((ia, a), (ib, b)):
            if not lo[i] <= 0.0 <= hi[i]:
                raise ValueError(
                    f"exclusive[{p}]: {nm!r} cannot be 0 (slider range [{lo[i]}, {hi[i]}])"
                )
        pairs.append((ia, ib))
    return pairs


def _slot_values(rig: FaceModel) -> dict[str, Any]:
    return {spec.name: rig.slot(spec.name) for fam in families() for spec in fam.slots}


def _build_model(
    rig: FaceModel,
    opt: NDArray[np.int64],
    B: NDArray[np.float64],
    space: str,
    m: int,
    iterations: int,
) -> FaceModel:
    shapes: list[BlendShape] = list(rig.shapes)
    for c, i in enumerate(opt):
        shapes[i] = shapes[i].replace(delta=B[c].astype(np.float32), vertex_mask=None)
    entry = {
        "operation": "refine_rig",
        "method": "Li et al. 2010 §3 (example-based facial rigging)",
        "space": space,
        "examples": int(m),
        "iterations": int(iterations),
        "refined_shapes": int(opt.size),
    }
    # the input's own class, with its neutral, parts and edits (same topology, so all still apply)
    return type(rig)(
        rig.vertices,
        rig.faces,
        shapes,
        polygons=rig.polygons,
        component_labels=rig.component_labels,
        component_names=rig.component_names,
        metadata=rig.metadata.with_provenance(entry),
        weights=dict(rig.weights),
        **_slot_values(rig),
    )
