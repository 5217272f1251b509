"""The identity PCA model ``b0 = m + P y`` (Bouaziz et al. 2013, §2; Blanz & Vetter 1999).

Bouaziz et al. build it from 200 scans of young adults (50 components) and
regularise the coefficients with ``β1 ||D_P y||²``, ``D_P`` the inverse
standard deviations. We have no scans, but the sample head's source does carry
real identity variation made by artists: MakeHuman's modelling targets
(``sample_models/head/identity``, CC0) — the 12 ethnicity × gender × age macro
targets of adults and the local modifiers of head, forehead, brows, eyes,
nose, cheeks, mouth and chin (``-incr``/``-decr`` pairs and the like).
:func:`sample_identity_model` draws people from them the way MakeHuman's
sliders combine them (ethnicity proportions from a flat Dirichlet, gender and
age uniform between the macro targets, every local modifier pair
``N(0, spread²)`` clipped to its range, each lone shape ``U(0, spread)``) and
keeps the principal components of those offsets.

The mean ``m`` is the template's own neutral, so ``y = 0`` is the template
and every identity the adaptive model had before still holds with the PCA off;
the components are those of the sampled people's offsets *from the template*
(uncentred: their second moment about ``m``). The sampled people's average is
not the template — lone modifiers only add, the macro mixtures are not the base
mesh — and a PCA of centred offsets left that direction (5.8 mm RMS over the
skin, more than the first centred component's 3.8 mm) out of the model: on
people it never saw, the neutral from one frame of points was 5.2 mm off with
50 components, against 1.9 mm now (``benchmarks/bench_identity_pca.py``).

:meth:`IdentityModel.fit` solves eq. 1's PCA part for given constraints,
``min ||A (m + P y) − c||² + β1 ||D_P y||²`` with ``β1`` in mm² as the
paper's (0.5: the data term's noise variance) — a ``l × l`` system; the adaptive
model (:class:`~workbench.capture.adapt.AdaptiveModel` with ``identity=``)
solves it jointly with the Laplacian correctives ``z0``.

Hand-written because it is an SVD and a ridge solve around numpy; the
sampling rules are MakeHuman's slider semantics, not a library's.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

__all__ = ["IdentityModel", "identity_targets", "sample_identities", "sample_identity_model"]

_PAIRS = (("incr", "decr"), ("up", "down"), ("in", "out"), ("forward", "backward"), ("compress", "uncompress"),
          ("convex", "concave"), ("open", "close"))
_MACRO = re.compile(r"^(african|asian|caucasian)-(female|male)-(young|old)$")


@dataclass(frozen=True)
class IdentityModel:
    """A PCA model of neutral faces ``b0 = m + P y`` (module docstring).

    Attributes
    ----------
    mean : (n, 3) float64
        ``m`` (the template's neutral).
    basis : (l, n, 3) float64
        ``P``: orthonormal over the stacked coordinates.
    std : (l,) float64
        Standard deviation of the sampled identities along each component (model units);
        ``D_P = diag(1 / std)``.
    metres_per_unit : float
        The model's units (``β1`` is in mm², as the paper's).
    """

    mean: NDArray[np.float64]
    basis: NDArray[np.float64]
    std: NDArray[np.float64]
    metres_per_unit: float = 1.0

    @property
    def n_components(self) -> int:
        return int(self.basis.shape[0])

    def truncated(self, n_components: int) -> IdentityModel:
        """The first ``n_components`` components (0 leaves only the mean)."""
        k = int(n_components)
        if not 0 <= k <= self.n_components:
            raise ValueError(f"n_components must be in [0, {self.n_components}], got {n_components!r}")
        return IdentityModel(self.mean, self.basis[:k], self.std[:k], self.metres_per_unit)

    def face(self, y: ArrayLike) -> NDArray[np.float64]:
        """``m + P y``, (n, 3), for ``y`` (l,)."""
        yv = np.asarray(y, np.float64).reshape(-1)
        if yv.shape != (self.n_components,):
            raise ValueError(f"y must have one coefficient per component ({self.n_components},), got {np.shape(y)}")
        return self.mean + np.tensordot(yv, self.basis, axes=(0, 0))

    def project(self, neutral: ArrayLike) -> NDArray[np.float64]:
        """Coefficients ``y = Pᵀ (b0 − m)`` of a neutral with the model's vertices (least squares, no prior)."""
        B = np.asarray(neutral, np.float64)
        if B.shape != self.mean.shape:
            raise ValueError(f"neutral must be {self.mean.shape}, got {B.shape}")
        return self.basis.reshape(self.n_components, -1) @ (B - self.mean).reshape(-1)

    def prior_weight(self, beta1: float = 0.5) -> float:
        """``β1`` in model units²: the paper's β1 = 0.5 is in mm² (a depth sensor's noise variance)."""
        return float(beta1) * (1e-3 / self.metres_per_unit) ** 2

    def fit(self, A: Any, c: ArrayLike, beta1: float = 0.5) -> NDArray[np.float64]:
        """``argmin_y ||A (m + P y) − c||² + β1 ||D_P y||²`` (eq. 1's PCA part) for constraint rows ``A`` (m, 3n).

        ``β1`` in mm² (:meth:`prior_weight`): with point constraints it is the
        variance of their noise, and the solution is the posterior mean of ``y``.
        """
        A_ = sp.csr_matrix(A) if sp.issparse(A) else np.asarray(A, np.float64)
        cv = np.asarray(c, np.float64).reshape(-1)
        n3 = self.mean.size
        if A_.shape[1] != n3 or A_.shape[0] != cv.size:
            raise ValueError(f"A must be (m, {n3}) and c (m,), got {A_.shape} and {cv.shape}")
        l_ = self.n_components
        if l_ == 0:
            return np.zeros(0)
        AP = np.asarray(A_ @ self.basis.reshape(l_, -1).T)
        r = cv - np.asarray(A_ @ self.mean.reshape(-1)).reshape(-1)
        H = AP.T @ AP + self.prior_weight(beta1) * np.diag(1.0 / self.std**2)
        return np.asarray(np.linalg.solve(H, AP.T @ r))


def identity_targets(folder: str | Path | None = None) -> dict[str, NDArray[np.float64]]:
    """The sample head's identity targets as dense deltas on its 5,084 base vertices (name -> (n, 3))."""
    from workbench.io.makehuman_target import parse_target
    from workbench.samples import sample_models_dir

    d = Path(folder) if folder is not None else sample_models_dir() / "head" / "identity"
    files = sorted(d.glob("*.target"))
    if not files:
        raise FileNotFoundError(f"identity_targets: no .target files in {d}")
    n = _base_vertex_count()
    return {p.name[: -len(".target")]: np.asarray(parse_target(p, n), np.float64) for p in files}


def _base_vertex_count() -> int:
    import json

    from workbench.samples import sample_models_dir

    return int(json.loads((sample_models_dir() / "head" / "manifest.json").read_text())["n_vertices"])


def _groups(names: list[str]) -> tuple[list[tuple[str, str]], list[str], dict[tuple[str, str, str], str]]:
    """Split target names into modifier pairs (positive, negative), lone shapes and the macro table."""
    macro: dict[tuple[str, str, str], str] = {}
    rest = []
    for name in names:
        m = _MACRO.match(name)
        if m:
            macro[(m.group(1), m.group(2), m.group(3))] = name
        else:
            rest.append(name)
    have = set(rest)
    pairs: list[tuple[str, str]] = []
    used: set[str] = set()
    for name in rest:
        stem, _, last = name.rpartition("-")
        for pos, neg in _PAIRS:
            if last == pos and f"{stem}-{neg}" in have:
                pairs.append((name, f"{stem}-{neg}"))
                used |= {name, f"{stem}-{neg}"}
    lone = [n for n in rest if n not in used]
    return pairs, lone, macro


def sample_identities(
    targets: Mapping[str, ArrayLike], n_samples: int = 400, *, spread: float = 0.35, seed: int = 0,
    neutral: ArrayLike | None = None, centre: bool = True,
) -> NDArray[np.float64]:
    """Offsets of ``n_samples`` random people from MakeHuman-style targets (module docstring), (S, n, 3).

    Parameters
    ----------
    targets : mapping name -> (n, 3) float
        Deltas; macro targets are recognised by their names (``<ethnicity>-<gender>-<young|old>``),
        modifier pairs by ``-incr``/``-decr`` (``up``/``down``, ``in``/``out``, …) suffixes.
    n_samples : int
    spread : float
        Standard deviation of a modifier pair's slider (the slider's range is [-1, 1]).
    seed : int
    neutral : (n, 3) float, optional
        The face the offsets apply to: each sampled face is then moved rigidly
        back onto it (the macro targets move the whole body, so the head also
        shifts and tilts; tracking finds the head pose, the identity must not).
    centre : bool
        Subtract the samples' mean (a population for a PCA). False: each offset is
        that person's face minus the template's — to draw a few people to test on (a
        single centred sample would be all zeros).
    """
    names = sorted(targets)
    pairs, lone, macro = _groups(names)
    rng = np.random.default_rng(seed)
    col = {name: j for j, name in enumerate(names)}
    W = np.zeros((int(n_samples), len(names)))  # slider values of every sampled person
    eth = sorted({e for e, _, _ in macro})
    full_macro = len(macro) == 4 * len(eth) and len(eth) > 0
    for s in range(int(n_samples)):
        if full_macro:
            p = rng.dirichlet(np.ones(len(eth)))
            g, a = rng.uniform(), rng.uniform()
            for e, pe in zip(eth, p, strict=True):
                for gender, wg in (("female", 1 - g), ("male", g)):
                    for age, wa in (("young", 1 - a), ("old", a)):
                        W[s, col[macro[(e, gender, age)]]] = pe * wg * wa
        for pos, neg in pairs:
            u = min(max(float(rng.normal(0.0, spread)), -1.0), 1.0)
            W[s, col[pos] if u > 0 else col[neg]] = abs(u)
        for name in lone:
            W[s, col[name]] = rng.uniform(0.0, spread)
    first = np.asarray(targets[names[0]], np.float64)
    T = np.stack([np.asarray(targets[name], np.float64).reshape(-1) for name in names])
    out = (W @ T).reshape(int(n_samples), *first.shape)
    if neutral is not None:
        from workbench.capture.pose import fit_rigid

        B = np.asarray(neutral, np.float64)
        for s in range(len(out)):
            M = fit_rigid(B + out[s], B)
            out[s] = (B + out[s]) @ M[:3, :3].T + M[:3, 3] - B
    return out - out.mean(axis=0) if centre else out


def sample_identity_model(
    model: Any = None,
    *,
    n_components: int = 50,
    n_samples: int = 400,
    spread: float = 0.35,
    seed: int = 0,
    targets: Mapping[str, ArrayLike] | None = None,
    progress: Callable[[float, str], Any] | None = None,
) -> IdentityModel:
    """The identity PCA of the sample head at ``model``'s resolution (base, or a Loop subdivision of it).

    Parameters
    ----------
    model : FaceModel, optional
        The sample head at any resolution :func:`~workbench.load_sample` gives (default: the base head);
        its neutral is the mean ``m``.
    n_components : int
        ``l`` (the paper uses 50).
    n_samples, spread, seed
        Of :func:`sample_identities`.
    targets : mapping, optional
        Deltas on the base head's vertices (default :func:`identity_targets`).

    Raises
    ------
    ValueError
        ``model`` is not the sample head at a Loop level of its base mesh; ``n_components`` out of range.
    """
    from workbench.geometry.subdivision import loop_subdivision, subdivided_vertex_count
    from workbench.samples import load_sample

    say = progress or (lambda f, msg: None)
    base = load_sample("head", "base")
    if model is None:
        model = base
    T = dict(targets) if targets is not None else identity_targets()
    say(0.1, "sampling identities")
    # offsets from the template, not centred: m is the template (the module docstring)
    X = sample_identities(T, n_samples, spread=spread, seed=seed, neutral=base.vertices, centre=False)
    n = int(model.n_vertices)
    if n != base.n_vertices:
        # the level from the vertex count alone; the operator is built once, for that level
        levels = next((lv for lv in (1, 2, 3) if subdivided_vertex_count(base.faces, base.n_vertices, lv) == n), 0)
        if not levels:
            raise ValueError(f"sample_identity_model: model has {n} vertices, not a Loop level of the sample head")
        S, _ = loop_subdivision(base.faces, base.n_vertices, levels)
        if not np.allclose(S @ np.asarray(base.vertices, np.float64), model.vertices, atol=1e-6):
            raise ValueError("sample_identity_model: model is not the sample head (its vertices differ)")
    else:
        S = None
    if not 1 <= int(n_components) <= len(X):
        raise ValueError(f"n_components must be in [1, {len(X)}], got {n_components!r}")
    say(0.5, "principal components")
    # the SVD through the samples' Gram matrix (S x S, S << 3n): 20x faster than a thin SVD here
    Xf = X.reshape(len(X), -1)
    lam, U = np.linalg.eigh(Xf @ Xf.T)
    k = int(n_components)
    order = np.argsort(lam)[::-1][:k]
    sv = np.sqrt(np.maximum(lam[order], 0.0))
    Vt = (U[:, order].T @ Xf) / np.maximum(sv, 1e-300)[:, None]
    basis = Vt.reshape(k, base.n_vertices, 3)
    std = sv / np.sqrt(len(X))  # the RMS coefficient about m
    if S is not None:
        # subdivision is linear: subdivided components, re-orthonormalised (QR keeps their order)
        sub = np.stack([S @ b for b in basis]).reshape(k, -1)
        q, r = np.linalg.qr(sub.T)
        basis = (q * np.sign(np.diag(r))).T.reshape(k, n, 3)
        std = std * np.abs(np.diag(r))
    say(1.0, "identity model ready")
    return IdentityModel(np.asarray(model.vertices, np.float64).copy(), basis, std,
                         float(model.metadata.metres_per_unit))
