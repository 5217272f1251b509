"""Where the offscreen camera stands: framed from the model's own axes and the extent of what it shows.

``reset_camera`` frames a bounding sphere and leaves faces small and off
centre in portrait-shaped heads, so the presets (:data:`CAMERAS`) place the
camera from ``metadata.up_axis`` / ``front_axis`` and the points' extent seen
from that direction.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pyvista as pv
from numpy.typing import ArrayLike, NDArray

from workbench import FaceModel
from workbench.geometry.axes import face_axes

__all__ = ["CAMERAS", "model_axes", "screen_positions", "setup_camera"]

#: Camera presets accepted by :func:`widgets.render.render_png`.
#: ``face`` is a front view framed on the vertices the blendshapes move
#: (the face itself, without neck and skull), used for thumbnails.
CAMERAS = ("front", "three_quarter", "side", "face")

_VIEW_ANGLE = 24.0  # degrees, vertical field of view: a mild "portrait lens"


def model_axes(model: FaceModel) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(up, front) unit vectors from the model metadata (:func:`workbench.geometry.axes.face_axes`)."""
    axes = face_axes(model)
    return axes[1], axes[2]


def _rotate(vec: NDArray, axis: NDArray, degrees: float) -> NDArray:
    """Rodrigues rotation of ``vec`` about unit ``axis``."""
    t = math.radians(degrees)
    return (
        vec * math.cos(t)
        + np.cross(axis, vec) * math.sin(t)
        + axis * float(axis @ vec) * (1 - math.cos(t))
    )


def _face_region(model: FaceModel) -> NDArray[np.bool_] | None:
    """(n,) bool: vertices moved by any blendshape, or None if there are none."""
    if not model.shapes:
        return None
    biggest = np.zeros(model.n_vertices)
    for shape in model.shapes:
        d = shape.effective_delta()
        np.maximum(biggest, np.abs(d).max(axis=1), out=biggest)
    # Many shapes drag the scalp and neck a hair's width; only clearly moved
    # vertices (1% of the model size) outline the face itself.
    v = np.asarray(model.vertices, dtype=np.float64)
    size = float(np.linalg.norm(np.ptp(v, axis=0)))
    for threshold in (0.01 * size, 1e-9):
        moved = biggest > threshold
        if moved.sum() >= 3:
            return moved
    return None


def _camera_for(
    model: FaceModel, points: NDArray, camera: str, aspect: float
) -> tuple[tuple, tuple, tuple]:
    """Camera (position, focal point, view up) framing ``points`` for a preset."""
    if camera not in CAMERAS:
        raise ValueError(f"render_png: camera must be one of {CAMERAS}, got {camera!r}")
    up, front = model_axes(model)
    pts = np.asarray(points, dtype=np.float64)
    if camera == "face":
        region = _face_region(model)
        if region is not None:
            pts = pts[region]
    direction = front
    if camera == "three_quarter":
        # turn toward the subject's left (viewer's right) and look down a little
        direction = _rotate(front, up, 35.0)
    elif camera == "side":
        direction = _rotate(front, up, 90.0)
    right = np.cross(up, direction)
    right /= np.linalg.norm(right)
    true_up = np.cross(direction, right)
    if camera in ("three_quarter", "side"):
        direction = _rotate(direction, right, -8.0)
        true_up = np.cross(direction, right)
    # extents in the view frame
    x, y, z = pts @ right, pts @ true_up, pts @ direction
    cx, cy = 0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max())
    half_w, half_h = 0.5 * np.ptp(x), 0.5 * np.ptp(y)
    margin = 1.08 if camera != "face" else 1.12
    tan_v = math.tan(math.radians(_VIEW_ANGLE / 2))
    dist = margin * max(half_h / tan_v, half_w / (tan_v * aspect))
    focal = cx * right + cy * true_up + float(z.mean()) * direction
    position = focal + direction * (dist + (z.max() - z.mean()))
    return tuple(position), tuple(focal), tuple(true_up)


def setup_camera(cam: Any, model: FaceModel, points: NDArray, camera: str, aspect: float) -> None:
    pos, focal, up = _camera_for(model, points, camera, aspect)
    cam.position, cam.focal_point, cam.up = pos, focal, up
    cam.view_angle = _VIEW_ANGLE


def screen_positions(
    model: FaceModel,
    xyz: ArrayLike,
    *,
    size: tuple[int, int] = (480, 480),
    camera: str = "front",
) -> NDArray[np.float64]:
    """Pixel coordinates of 3D points in a :func:`render_png` picture.

    Uses the same camera as ``render_png(model, ..., size=size, camera=camera)``
    (framed on the neutral mesh, so it does not depend on weights). Handy for
    tests (which pixels show the mouth?) and for aiming the mouse in browser
    tests.

    Parameters
    ----------
    xyz : (k, 3) float
        World positions.

    Returns
    -------
    (k, 2) float
        ``(column, row)`` with the origin at the top-left pixel corner.
    """
    w, h = int(size[0]), int(size[1])
    cam = pv.Camera()
    setup_camera(cam, model, np.asarray(model.vertices), camera, w / h)
    m = np.array(
        [
            [
                cam.GetCompositeProjectionTransformMatrix(w / h, -1, 1).GetElement(i, j)
                for j in range(4)
            ]
            for i in range(4)
        ]
    )
    p = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    hom = np.c_[p, np.ones(len(p))] @ m.T
    ndc = hom[:, :2] / hom[:, 3:4]
    return np.c_[(ndc[:, 0] + 1) * 0.5 * w, (1 - ndc[:, 1]) * 0.5 * h]
