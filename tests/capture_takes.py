"""Shared pieces of the capture tests' generated takes."""

from __future__ import annotations

import numpy as np

from workbench.capture import synthetic_performance
from workbench.capture.rig import ExpressionSpace


def marker_visible_shapes(model, seed: int = 1) -> np.ndarray:
    """Indices of the shapes that move one of the default 100 face markers by > 0.5 % of the head.

    (The eyeball and tongue shapes move no skin marker: a marker take cannot see them.)
    """
    space = ExpressionSpace.from_model(model)
    probe = synthetic_performance(model, 1, seed=seed)
    _, D = space.marker_basis(probe.marker_ids)
    return np.flatnonzero(np.linalg.norm(D, axis=1).max(0) > 0.005 * space.size)


def warped_actor(head):
    """The capture tests' actor: ``head`` smoothly warped (a longer nose and chin, other proportions;
    markers up to 9 mm off the rig's neutral), as a :class:`SmoothWarp` in the head's own units."""
    from workbench.rigging.synthetic import SmoothWarp

    V = head.vertices
    lo, hi = V.min(0), V.max(0)
    size = float(np.linalg.norm(hi - lo))
    centre = 0.5 * (lo + hi)
    return SmoothWarp(
        centres=centre + np.array([[0.0, -0.3, 0.6], [0.0, 0.2, 0.9]]),
        radii=np.array([0.25, 0.15]) * size,
        amplitudes=np.array([[0.0, -0.01, 0.015], [0.0, 0.0, 0.02]]) * size,
        scale=np.array([1.03, 0.98, 1.01]),
    )


# ----------------------------------------------------------------- a rendered video take (ui)
#: the rendered take: 480×480 frames of the sample head, jawOpen ramp 0 → 1, a blink, yaw ±10°, nod 4°
SIZE = (480, 480)
T = 30
JAW = np.linspace(0.0, 1.0, T)
BLINK = np.zeros(T)
BLINK[12:18] = [0.5, 1.0, 1.0, 1.0, 1.0, 0.5]
YAW = np.deg2rad(10.0) * np.sin(np.linspace(0.0, 2.0 * np.pi, T))
PITCH = np.deg2rad(4.0) * np.sin(np.linspace(0.0, np.pi, T))


def _ramp(T: int, a: int, b: int, peak: float, hold: int = 4) -> np.ndarray:
    """0 → ``peak`` → 0 over frames ``a``..``b`` (eased up, held ``hold`` frames, eased down)."""
    w = np.zeros(T)
    up = (b - a - hold) // 2
    u = np.linspace(0.0, 1.0, up + 1)[1:]
    ease = u * u * (3 - 2 * u)
    w[a + 1 : a + 1 + up] = peak * ease
    w[a + 1 + up : a + 1 + up + hold] = peak
    w[a + 1 + up + hold : a + 1 + 2 * up + hold] = peak * ease[::-1]
    return w


def full_take() -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """The issue's whole video take, 150 frames (5 s at 30 fps): ``(weights by ARKit name, yaw, pitch)``.

    Neutral (10 frames), the jaw opening and closing with a blink on the way, a smile whose
    right side starts 4 frames late and peaks lower, the brows (inner up, then the outer ones
    up, one higher), then all of it at once at half strength; the head turns ±12° and nods
    ±5° throughout. Every other shape is 0.
    """
    T = 150
    W = {n: np.zeros(T) for n in ("jawOpen", "eyeBlinkLeft", "eyeBlinkRight", "mouthSmileLeft", "mouthSmileRight",
                                  "browInnerUp", "browOuterUpLeft", "browOuterUpRight")}
    W["jawOpen"] += _ramp(T, 10, 40, 0.9)
    blink = np.zeros(T)
    blink[22:28] = [0.5, 1.0, 1.0, 1.0, 1.0, 0.5]
    W["eyeBlinkLeft"] += blink
    W["eyeBlinkRight"] += blink
    W["mouthSmileLeft"] += _ramp(T, 40, 70, 0.9)
    W["mouthSmileRight"] += np.roll(_ramp(T, 40, 70, 0.7), 4)
    W["browInnerUp"] += _ramp(T, 70, 95, 0.9)
    W["browOuterUpLeft"] += _ramp(T, 85, 112, 0.8)
    W["browOuterUpRight"] += _ramp(T, 85, 112, 0.6)
    for name in ("jawOpen", "mouthSmileLeft", "mouthSmileRight", "browInnerUp"):
        W[name] += _ramp(T, 115, 148, 0.5, hold=8)
    t = np.linspace(0.0, 1.0, T)
    return W, np.deg2rad(12.0) * np.sin(2.0 * np.pi * 1.5 * t), np.deg2rad(5.0) * np.sin(2.0 * np.pi * t)


#: the expressions of :func:`other_take`, in order, with their peaks
OTHER_EXPRESSIONS = (("mouthPucker", 0.9), ("eyeSquintLeft", 0.8), ("mouthLeft", 0.8), ("cheekPuff", 0.9),
                     ("mouthFunnel", 0.8), ("noseSneerRight", 0.9), ("mouthPressLeft", 0.8), ("browDownLeft", 0.8),
                     ("mouthRollLower", 0.8), ("jawLeft", 0.7))


def other_take() -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """A held-out video take of ten expressions the whole take does not show, 180 frames (6 s at 30 fps).

    :data:`OTHER_EXPRESSIONS` one after another (eased up, held, eased down, 16 frames each), some
    with a weaker partner (the right squint at 0.6 of the left, the right brow 3 frames late at 0.7,
    the jaw a little open in the "oo"); the head turns ±10° and nods ±4° throughout.
    """
    T = 180
    W: dict[str, np.ndarray] = {}
    for i, (name, peak) in enumerate(OTHER_EXPRESSIONS):
        W[name] = _ramp(T, 6 + 17 * i, 6 + 17 * i + 16, peak, hold=4)
    W["eyeSquintRight"] = 0.6 * W["eyeSquintLeft"]
    W["browDownRight"] = np.roll(0.7 * W["browDownLeft"], 3)
    W["jawOpen"] = 0.3 * W["mouthFunnel"]
    t = np.linspace(0.0, 1.0, T)
    return W, np.deg2rad(10.0) * np.sin(2 * np.pi * 1.2 * t + 0.7), np.deg2rad(4.0) * np.sin(2 * np.pi * 0.8 * t)


def render_take(model, take=None, pose=None):
    """(T, 480, 480, 3) uint8 frames of ``model`` playing a take (needs pyvista).

    ``take``: ``(weights by shape name, yaw, pitch)`` (:func:`full_take`); default the short take
    above (jaw ramp, blink, head turn). ``pose(weights) -> (n, 3)`` makes the mesh (default
    the model's own shapes: neutral + weighted deltas; a
    :class:`~workbench.testing.GeneratedFace`'s ``pose`` renders a face from its source's weights).
    """
    from widgets.render import png_to_array, render_png

    if take is None:
        take = ({"jawOpen": JAW, "eyeBlinkLeft": BLINK, "eyeBlinkRight": BLINK}, YAW, PITCH)
    weights, yaw, pitch = take
    V0 = np.asarray(model.vertices, np.float64)
    if pose is None:
        names = list(model.shape_names)
        deltas = {k: np.asarray(model.shapes[names.index(k)].delta, np.float64) for k in weights}

        def pose(w):
            return V0 + sum(v * deltas[k] for k, v in w.items())

    centre = V0.mean(0)
    frames = []
    for f in range(len(yaw)):
        X = pose({k: float(v[f]) for k, v in weights.items()})
        cy, sy, cp, sp = np.cos(yaw[f]), np.sin(yaw[f]), np.cos(pitch[f]), np.sin(pitch[f])
        R = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]]) @ np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
        png = render_png(model, points=(X - centre) @ R.T + centre, size=SIZE, camera="front", antialias=False)
        frames.append(png_to_array(png))
    return np.stack(frames)


def write_y4m(path, frames, fps=30):
    """RGB (T, h, w, 3) uint8 frames as a 4:2:0 YUV4MPEG2 file (BT.601, full range), what Chromium's fake camera reads."""
    T, h, w, _ = frames.shape
    rgb = frames.astype(np.float64)
    y = 0.299 * rgb[..., 0] + 0.587 * rgb[..., 1] + 0.114 * rgb[..., 2]
    u = 128.0 - 0.168736 * rgb[..., 0] - 0.331264 * rgb[..., 1] + 0.5 * rgb[..., 2]
    v = 128.0 + 0.5 * rgb[..., 0] - 0.418688 * rgb[..., 1] - 0.081312 * rgb[..., 2]

    def half(c):
        return c.reshape(T, h // 2, 2, w // 2, 2).mean(axis=(2, 4))

    with open(path, "wb") as fh:
        fh.write(f"YUV4MPEG2 W{w} H{h} F{fps}:1 Ip A1:1 C420jpeg\n".encode())
        for f in range(T):
            fh.write(b"FRAME\n")
            for plane in (y[f], half(u)[f], half(v)[f]):
                fh.write(np.clip(np.rint(plane), 0, 255).astype(np.uint8).tobytes())


def zoomed(img: np.ndarray, s: float) -> np.ndarray:
    """``img`` scaled by ``s`` about its centre, cropped or padded with its corner's colour (the background).

    The actor ``1/s`` times the distance from the camera (a weak-perspective camera: the face is
    small in the frame and the lens's change of perspective is left out)."""
    from PIL import Image

    h, w = img.shape[:2]
    a = np.asarray(Image.fromarray(img).resize((round(w * s), round(h * s)), Image.BILINEAR))
    H, W = a.shape[:2]
    if s >= 1:
        y0, x0 = (H - h) // 2, (W - w) // 2
        return a[y0:y0 + h, x0:x0 + w].copy()
    out = np.empty_like(img)
    out[:] = img[0, 0]
    y0, x0 = (h - H) // 2, (w - W) // 2
    out[y0:y0 + H, x0:x0 + W] = a
    return out
