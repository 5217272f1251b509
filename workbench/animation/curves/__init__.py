"""Keyframes and animation curves: :class:`Key`, :class:`Track`, tangents, interpolation, head rotations.

A :class:`Track` holds the keys of one animated quantity and evaluates its
curve (:mod:`~workbench.animation.curves.track`); a
:class:`~workbench.animation.tracks.Timeline` holds the tracks. Track names say
what a track animates (:mod:`~workbench.animation.curves.names`). Keys, their
interpolation and tangents (Blender's auto-clamped rule) are in
:mod:`~workbench.animation.curves.keys`; quaternions and head rotations in
:mod:`~workbench.animation.curves.rotations`.

Hand-written because no kept dependency has keyframe curves; scipy's
``CubicHermiteSpline`` would evaluate the segments but not the per-key
interpolation modes or clamping rules.
"""

from __future__ import annotations

from workbench.animation.curves.keys import (
    INTERPOLATIONS,
    TANGENT_MODES,
    Interpolation,
    Key,
    TangentMode,
    auto_clamped_slopes,
)
from workbench.animation.curves.names import (
    HEAD_POSE,
    WEIGHTS_PREFIX,
    TrackError,
    weight_track_name,
)
from workbench.animation.curves.rotations import (
    IDENTITY_POSE,
    head_euler_from_rotation,
    head_rotation_from_euler,
    quat_slerp,
    quaternion_to_matrix,
)
from workbench.animation.curves.track import Track

__all__ = [
    "HEAD_POSE",
    "IDENTITY_POSE",
    "INTERPOLATIONS",
    "TANGENT_MODES",
    "WEIGHTS_PREFIX",
    "Interpolation",
    "Key",
    "TangentMode",
    "Track",
    "TrackError",
    "auto_clamped_slopes",
    "head_euler_from_rotation",
    "head_rotation_from_euler",
    "quat_slerp",
    "quaternion_to_matrix",
    "weight_track_name",
]
