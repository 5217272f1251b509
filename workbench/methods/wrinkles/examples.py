"""Procedural detailed example poses for the sample head (no scan data with real wrinkles exists).

Pose-space wrinkles (:mod:`workbench.methods.wrinkles.pose_space`) learn from *detailed*
example meshes. The sample head's ARKit blendshapes are smooth, and there is
no permissively licensed scan with expression wrinkles, so this module sculpts
them procedurally — the same rule for the few example poses and for every
frame of a longer "performance", which then serves as ground truth.

The sculpt (units are the model's: decimetres for the sample head)
------------------------------------------------------------------
For an expression with blend weights ``w`` the large-scale mesh is the blend
``X = neutral + Σ_k w_k δ_k``. Five wrinkle *families* are laid on it along
the normal of ``X``::

    h(v) = Σ_r A_r · m_r(v) · tanh(c_r(v) / c0_r) · profile_r(s_r(v) / λ_r)

* ``s_r`` is a phase field on the rest mesh (furrows run along its level sets):
  forehead ``y − κx²`` (horizontal, slightly arched furrows), glabella ``x``
  (vertical lines between the brows), crow's feet ``ρ·θ`` (θ the angle around
  the outer eye corner: radial lines), nasolabial fold (signed distance to the
  nose-wing → mouth-corner line: one deep groove with the cheek bulging over
  it), lips ``x`` (vertical lip lines).
* ``c_r`` is the **compression** of the skin along ``∇s_r`` (across the
  furrows): per triangle ``max(0, 1 − ‖J ĝ‖)`` with ``J`` the deformation
  gradient from the neutral to ``X`` and ``ĝ`` the unit phase gradient,
  averaged to vertices and smoothed by implicit diffusion over a radius of
  ``smooth_r``. So wrinkles appear only where — and as much as — the
  expression squeezes the skin, and vanish at the neutral.
* ``m_r`` is a soft region mask around landmarks of the sample head
  (:class:`Landmarks`; pass your own for another face), ``A_r`` the amplitude
  (0.4–1.2 mm), ``λ_r`` the wavelength (3–7 mm; the ~100k head has ~1 mm edges),
  ``profile`` a narrow groove with a gentle bulge between grooves.

:data:`EXAMPLE_POSES` are six expressions (brow raise, brow down, squint,
smile, pucker, surprise), each symmetric; :func:`performance_weights` makes a
smooth ``T``-frame weight sequence that also contains one-sided and mixed
expressions not among the examples (what weighted PSD is for).

Hand-written because it is a synthetic data generator specific to this
project; the geometry operators are libigl's and the solves CHOLMOD/SuperLU's.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import igl
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from workbench.arkit import rig_weights
from workbench.geometry.normals import vertex_normals
from workbench.geometry.operators import cotangent_laplacian, mass_matrix
from workbench.geometry.sparse_cholesky import SparseSPDSolver

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel

Weights = Mapping[str, float]

#: the six detailed example expressions (symmetric); the rest pose is added by the fit
EXAMPLE_POSES: dict[str, dict[str, float]] = {
    "brow_raise": {"browInnerUp": 1.0, "browOuterUpLeft": 1.0, "browOuterUpRight": 1.0},
    "brow_down": {"browDownLeft": 1.0, "browDownRight": 1.0, "noseSneerLeft": 0.3, "noseSneerRight": 0.3},
    "squint": {"eyeSquintLeft": 1.0, "eyeSquintRight": 1.0, "cheekSquintLeft": 0.8, "cheekSquintRight": 0.8},
    "smile": {"mouthSmileLeft": 1.0, "mouthSmileRight": 1.0, "cheekSquintLeft": 0.5, "cheekSquintRight": 0.5},
    "pucker": {"mouthPucker": 1.0, "mouthFunnel": 0.3},
    "surprise": {
        "browInnerUp": 0.8,
        "browOuterUpLeft": 0.8,
        "browOuterUpRight": 0.8,
        "jawOpen": 0.4,
        "eyeWideLeft": 0.6,
        "eyeWideRight": 0.6,
    },
}


@dataclass(frozen=True)
class Landmarks:
    """Rest-pose landmarks (model units) of the +x (subject's left) side; mirrored for the right.

    Defaults are measured on the sample head (decimetres, +y up, face toward +z).
    """

    brow_y: float = 7.46
    forehead_top_y: float = 8.0
    forehead_half_width: float = 0.55
    glabella: tuple[float, float] = (0.0, 7.40)
    eye_corner: tuple[float, float] = (0.52, 7.29)
    nose_wing: tuple[float, float] = (0.17, 6.86)
    mouth_corner_out: tuple[float, float] = (0.34, 6.50)
    mouth_centre: tuple[float, float] = (0.0, 6.62)
    mouth_radii: tuple[float, float] = (0.30, 0.15)
    front_z: float = 1.0  # only vertices in front of this z get wrinkles (the face, not the ears)


@dataclass(frozen=True)
class Family:
    """One wrinkle family: amplitude ``A`` (units), wavelength, compression scale, smoothing radius."""

    amplitude: float
    wavelength: float
    c0: float = 0.06
    smooth_r: float = 0.06


@dataclass(frozen=True)
class SculptParams:
    """Amplitude / frequency parameters of the procedural sculpt (model units, dm for the sample).

    ``scale_wavelength`` multiplies every wavelength (coarser meshes need longer
    waves: ~1 mm edges at 100k, ~2 mm at 25k, ~4.5 mm at the base resolution).
    """

    forehead: Family = Family(0.008, 0.07, c0=0.05, smooth_r=0.12)
    glabella: Family = Family(0.007, 0.05, c0=0.05, smooth_r=0.06)
    crows_feet: Family = Family(0.006, 0.045, c0=0.05, smooth_r=0.06)
    nasolabial: Family = Family(0.012, 0.03, c0=0.06, smooth_r=0.06)
    lips: Family = Family(0.004, 0.03, c0=0.05, smooth_r=0.04)
    forehead_arch: float = 0.35
    scale_wavelength: float = 1.0
    scale_amplitude: float = 1.0
    landmarks: Landmarks = field(default_factory=Landmarks)

    @property
    def families(self) -> dict[str, Family]:
        return {
            "forehead": self.forehead,
            "glabella": self.glabella,
            "crows_feet": self.crows_feet,
            "nasolabial": self.nasolabial,
            "lips": self.lips,
        }

    def for_resolution(self, n_vertices: int) -> SculptParams:
        """Wavelengths stretched so a wave spans >= ~4 edges on coarse sample meshes."""
        f = 1.0 if n_vertices >= 60_000 else 2.0 if n_vertices >= 15_000 else 3.5
        return replace(self, scale_wavelength=self.scale_wavelength * f)


def _smoothstep(e0: float, e1: float, x: NDArray) -> NDArray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _groove(u: NDArray) -> NDArray:
    """Periodic furrow: narrow valleys at integer u, gentle crests between (zero mean)."""
    return 0.3125 - np.abs(np.cos(np.pi * u)) ** 6


class WrinkleSculptor:
    """Procedural detailed poses for one mesh (precomputes operators once).

    Parameters
    ----------
    model : FaceModel
        Gives the neutral, the faces, the blendshapes and the skin component.
    params : SculptParams, optional
        Default: :class:`SculptParams` adapted to the mesh resolution.
    """

    def __init__(self, model: FaceModel, params: SculptParams | None = None) -> None:
        self.model = model
        self.params = params or SculptParams().for_resolution(model.n_vertices)
        V = np.asarray(model.vertices, np.float64)
        Fc = np.asarray(model.faces, np.int64)
        self.V, self.F = V, Fc
        n = V.shape[0]
        names = model.component_names
        skin = np.zeros(n, bool)
        if "skin" in names:
            skin[model.component_vertices("skin")] = True
        else:
            skin[:] = True
        lm = self.params.landmarks
        self.skin = skin
        x, y, z = V[:, 0], V[:, 1], V[:, 2]
        ax = np.abs(x)
        front = skin & (z > lm.front_z)
        # --- phase fields s_r on the rest mesh and their region masks m_r
        phase: dict[str, NDArray] = {}
        mask: dict[str, NDArray] = {}
        phase["forehead"] = y - self.params.forehead_arch * x**2
        mask["forehead"] = (
            _smoothstep(lm.brow_y - 0.03, lm.brow_y + 0.03, y)
            * (1 - _smoothstep(lm.forehead_top_y - 0.15, lm.forehead_top_y, y))
            * (1 - _smoothstep(lm.forehead_half_width - 0.12, lm.forehead_half_width, ax))
        )
        gx, gy = lm.glabella
        phase["glabella"] = x.copy()
        mask["glabella"] = np.exp(-(((x - gx) / 0.13) ** 4) - ((y - gy) / 0.11) ** 4)
        ex, ey = lm.eye_corner
        dx, dy = ax - ex, y - ey
        rho = 0.15
        theta = np.arctan2(dy, dx)  # 0 = laterally outward, cut at the medial side (masked out)
        phase["crows_feet"] = rho * theta * np.sign(x + 1e-12)
        r = np.hypot(dx, dy)
        mask["crows_feet"] = (
            _smoothstep(0.02, 0.05, r) * (1 - _smoothstep(0.17, 0.24, r)) * (1 - _smoothstep(0.9, 1.3, np.abs(theta)))
        )
        a = np.array(lm.nose_wing)
        b = np.array(lm.mouth_corner_out)
        seg = b - a
        L = float(np.linalg.norm(seg))
        tdir = seg / L
        ndir = np.array([tdir[1], -tdir[0]])  # points laterally (+x) for the left side
        if ndir[0] < 0:
            ndir = -ndir
        px, py = ax - a[0], y - a[1]
        along = (px * tdir[0] + py * tdir[1]) / L
        phase["nasolabial"] = (px * ndir[0] + py * ndir[1]) * np.sign(x + 1e-12)
        mask["nasolabial"] = _smoothstep(-0.15, 0.05, along) * (1 - _smoothstep(0.95, 1.2, along))
        mask["nasolabial"] *= np.exp(-((phase["nasolabial"] / 0.08) ** 2))
        mx, my = lm.mouth_centre
        rx, ry = lm.mouth_radii
        e = ((x - mx) / rx) ** 2 + ((y - my) / ry) ** 2
        phase["lips"] = x.copy()
        mask["lips"] = 1 - _smoothstep(0.6, 1.0, e)
        self.families = self.params.families
        self.phase = phase
        self.mask = {k: (m * front).astype(np.float64) for k, m in mask.items()}
        # --- per-face unit phase gradients, written as rest-edge coordinates (a, b): ĝ = a e1 + b e2
        G = igl.grad(V, Fc)
        m = Fc.shape[0]
        e1 = V[Fc[:, 1]] - V[Fc[:, 0]]
        e2 = V[Fc[:, 2]] - V[Fc[:, 0]]
        g11, g12, g22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
        det = g11 * g22 - g12 * g12
        det = np.where(np.abs(det) > 1e-30, det, 1e-30)
        self._coef: dict[str, NDArray] = {}
        for k in self.families:
            g = np.asarray(G @ phase[k]).reshape(3, m).T
            g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
            r1, r2 = (g * e1).sum(1), (g * e2).sum(1)
            self._coef[k] = np.stack([(g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det], 1)
        # --- face -> vertex averaging (area weighted) and the diffusion smoother per radius
        area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
        rows = Fc.ravel()
        cols = np.repeat(np.arange(m), 3)
        inc = sp.csr_matrix((np.repeat(area, 3), (rows, cols)), shape=(n, m))
        s = np.asarray(inc.sum(1)).ravel()
        self._face_to_vertex = sp.diags(1.0 / np.maximum(s, 1e-30)) @ inc
        Lc = cotangent_laplacian(V, Fc)
        M = mass_matrix(V, Fc)
        Md = M.diagonal()
        Md = np.where(Md > 0, Md, Md[Md > 0].mean())
        self._M = sp.diags(Md)
        self._smoothers: dict[float, SparseSPDSolver] = {}
        for fam in self.families.values():
            t = fam.smooth_r**2
            if t not in self._smoothers:
                self._smoothers[t] = SparseSPDSolver(sp.csc_matrix(self._M - t * Lc))
        self._names = list(model.shape_names)
        self._deltas = {s.name: s.effective_delta() for s in model.shapes if not s.mute}

    # ------------------------------------------------------------------ pieces
    def blend(self, weights: Weights) -> NDArray[np.float64]:
        """``neutral + Σ w_k δ_k`` for the named weights (others 0), (n, 3) float64.

        Names are the rig's own or ARKit's (any spelling, split halves and
        merged pairs resolved by :func:`workbench.arkit.rig_weights`).
        """
        own = {n: w for n, w in weights.items() if n in self._names}
        rest, missing = rig_weights({n: w for n, w in weights.items() if n not in self._names}, self._names)
        if missing:
            raise KeyError(
                f"WrinkleSculptor.blend: the rig has no shape for {missing} (nor split halves of it); "
                f"its shapes are {self._names[:6]}..."
            )
        X = self.V.copy()
        for name, w in {**rest, **own}.items():
            if w and name in self._deltas:
                X += float(w) * self._deltas[name]
        return X

    def compression(self, X: ArrayLike) -> dict[str, NDArray[np.float64]]:
        """Smoothed per-vertex compression across each family's furrows, (n,) each, >= 0."""
        P = np.asarray(X, np.float64)
        Fc = self.F
        d1 = P[Fc[:, 1]] - P[Fc[:, 0]]
        d2 = P[Fc[:, 2]] - P[Fc[:, 0]]
        out: dict[str, NDArray[np.float64]] = {}
        by_radius: dict[float, list[str]] = {}
        raw: dict[str, NDArray] = {}
        for k, fam in self.families.items():
            c = self._coef[k]
            stretch = np.linalg.norm(c[:, :1] * d1 + c[:, 1:] * d2, axis=1)
            raw[k] = self._face_to_vertex @ np.maximum(0.0, 1.0 - stretch)
            by_radius.setdefault(fam.smooth_r**2, []).append(k)
        for t, keys in by_radius.items():
            rhs = self._M @ np.stack([raw[k] for k in keys], 1)
            sm = self._smoothers[t].solve(rhs)
            for i, k in enumerate(keys):
                out[k] = np.maximum(np.asarray(sm)[:, i], 0.0)
        return out

    def height(self, X: ArrayLike) -> NDArray[np.float64]:
        """Wrinkle height along the normal for a large-scale mesh ``X`` (n,) float64."""
        comp = self.compression(X)
        p = self.params
        h = np.zeros(self.V.shape[0])
        for k, fam in self.families.items():
            lam = fam.wavelength * p.scale_wavelength
            u = self.phase[k] / lam
            prof = (
                -np.exp(-(u**2)) + 0.6 * np.exp(-(((u - 1.8) / 1.2) ** 2))
                if k == "nasolabial"
                else _groove(u)
            )
            h += fam.amplitude * p.scale_amplitude * self.mask[k] * np.tanh(comp[k] / fam.c0) * prof
        return h

    def detailed(self, weights: Weights) -> NDArray[np.float32]:
        """The detailed mesh of an expression: blend + wrinkles along the blend's normals, (n, 3) float32."""
        X = self.blend(weights)
        return self.detail_of(X)

    def detail_of(self, X: ArrayLike) -> NDArray[np.float32]:
        """Any large-scale mesh ``X`` (n, 3) plus its procedural wrinkles, (n, 3) float32."""
        P = np.asarray(X, np.float64)
        h = self.height(P)
        return (P + h[:, None] * vertex_normals(P, self.F)).astype(np.float32)

    def examples(self, poses: Mapping[str, Weights] | None = None) -> dict[str, NDArray[np.float32]]:
        """Detailed meshes of the example expressions (default :data:`EXAMPLE_POSES`)."""
        return {k: self.detailed(w) for k, w in (poses or EXAMPLE_POSES).items()}

    def sequence(self, weights: Sequence[Weights]) -> NDArray[np.float32]:
        """Detailed meshes of a weight sequence, (T, n, 3) float32."""
        return np.stack([self.detailed(w) for w in weights])


def example_poses_for(
    shape_names: Sequence[str], poses: Mapping[str, Weights] | None = None
) -> tuple[dict[str, dict[str, float]], dict[str, str]]:
    """The example poses (default :data:`EXAMPLE_POSES`) on a rig's own shape names, and what was left out.

    Returns ``(poses, skipped)``: each buildable pose with its weights on the rig
    (:func:`workbench.arkit.rig_weights`); ``skipped`` maps a pose the rig cannot
    express to why (the ARKit shapes it lacks). A pose that keeps at least half
    of its weight is built without the missing shapes, and reported too.
    """
    out: dict[str, dict[str, float]] = {}
    skipped: dict[str, str] = {}
    for pose, weights in (poses or EXAMPLE_POSES).items():
        rig, missing = rig_weights(weights, shape_names)
        total = sum(abs(w) for w in weights.values())
        lost = sum(abs(w) for n, w in weights.items() if n in missing)
        if not rig or lost > 0.5 * total:
            skipped[pose] = f"the rig has no shape for {missing}"
            continue
        if missing:
            skipped[pose] = f"built without {missing} (the rig has no such shapes)"
        out[pose] = rig
    return out, skipped


# --------------------------------------------------------------------------- performance


def _envelope(t: NDArray, start: float, length: float) -> NDArray:
    """Smooth bump: smoothstep ramp in (25 %, at least 4 frames), hold, ramp out."""
    length = max(length, 8.0)
    ramp = max(0.25 * length, 4.0)
    up = _smoothstep(start, start + ramp, t)
    down = 1 - _smoothstep(start + length - ramp, start + length, t)
    return up * down


def _sided(weights: Weights, side: str) -> dict[str, float]:
    """Keep one side of an expression ('left'/'right'): the other side's shapes at 10 %,
    central shapes at 50 % (the sample has no one-sided browInnerUp/pucker)."""
    if side == "both":
        return dict(weights)
    keep, drop = ("Left", "Right") if side == "left" else ("Right", "Left")
    out = {}
    for k, w in weights.items():
        if k.endswith(keep):
            out[k] = w
        elif k.endswith(drop):
            out[k] = 0.1 * w
        else:
            out[k] = 0.5 * w
    return out


def performance_weights(
    n_frames: int = 150,
    *,
    seed: int = 7,
    poses: Mapping[str, Weights] | None = None,
    events_per_half: int = 7,
) -> list[dict[str, float]]:
    """A smooth "performance": ``n_frames`` weight dicts from overlapping expression events.

    Each half of the sequence has ``events_per_half`` events (an example
    expression, on both sides or only one, at 50–100 %, lasting 15–30 % of the
    half); the first half contains every example expression at least once, so
    training on it and testing on the second half is meaningful. Overlapping
    events add up (mixed expressions); weights are clipped to [0, 1].
    Deterministic for a given seed.
    """
    if n_frames < 2:
        raise ValueError(f"performance_weights: need n_frames >= 2, got {n_frames}")
    poses = dict(poses or EXAMPLE_POSES)
    names = list(poses)
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames, dtype=np.float64)
    half = n_frames / 2
    events: list[tuple[str, str, float, float, float]] = []
    for h in range(2):
        order = list(rng.permutation(names)) if h == 0 else list(rng.choice(names, events_per_half))
        order = (order + list(rng.choice(names, max(0, events_per_half - len(order)))))[:events_per_half]
        if h == 0 and len(order) < len(names):
            order = list(rng.permutation(names))
        slots = np.sort(rng.uniform(0, 1, len(order)))
        for i, name in enumerate(order):
            length = half * rng.uniform(0.15, 0.3)
            start = h * half + slots[i] * (half - length)
            side = str(rng.choice(["both", "both", "left", "right"]))
            events.append((str(name), side, float(rng.uniform(0.5, 1.0)), float(start), float(length)))
    shapes = sorted({k for w in poses.values() for k in w})
    W = np.zeros((n_frames, len(shapes)))
    col = {k: i for i, k in enumerate(shapes)}
    for name, side, amp, start, length in events:
        env = amp * _envelope(t, start, length)
        for k, w in _sided(poses[name], side).items():
            W[:, col[k]] += env * w
    W = np.clip(W, 0.0, 1.0)
    return [{k: float(W[f, col[k]]) for k in shapes} for f in range(n_frames)]
