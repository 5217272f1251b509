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


def render_take(model):
    """(T, 480, 480, 3) uint8 frames of ``model`` playing the take above (needs pyvista)."""
    from widgets.render import png_to_array, render_png

    names = list(model.shape_names)
    V0 = np.asarray(model.vertices, np.float64)
    centre = V0.mean(0)
    deltas = {k: np.asarray(model.shapes[names.index(k)].delta, np.float64)
              for k in ("jawOpen", "eyeBlinkLeft", "eyeBlinkRight")}
    frames = []
    for f in range(T):
        X = V0 + JAW[f] * deltas["jawOpen"] + BLINK[f] * (deltas["eyeBlinkLeft"] + deltas["eyeBlinkRight"])
        cy, sy, cp, sp = np.cos(YAW[f]), np.sin(YAW[f]), np.cos(PITCH[f]), np.sin(PITCH[f])
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
