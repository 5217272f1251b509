"""Live Link Face conventions: its header columns, timecodes, frame rate and head angles.

Live Link Face (Epic's iPhone app; also what :mod:`workbench.export.csv`
writes with ``style="livelink"``) writes the header
``Timecode,BlendShapeCount,EyeBlinkLeft,...,TongueOut`` (the 52 ARKit
columns, :data:`LIVELINK_SHAPE_COLUMNS`), then ``HeadYaw,HeadPitch,HeadRoll``
and six eye angles (:data:`LIVELINK_HEADER`). ``Timecode`` is
``HH:MM:SS:FF.mmm``: frame number ``FF`` plus thousandths of a frame, as
Epic's ``LiveLinkFaceImporter`` reads it. The recording rate is ``fps`` if
given, else inferred from the frame numbers (:func:`livelink_fps`, after
Epic's importer, which reads 60 when a frame number exceeds 30 and 30
otherwise): 60 when a frame number reaches 30, 30 when the take crosses a
second boundary without one, else 60 (the app's default; a take within one
second cannot tell 30 from 60 — pass ``fps``). The head columns are angles
over :data:`LIVELINK_ANGLE_UNIT` (see :func:`livelink_head_rotation`).
"""

from __future__ import annotations

import re

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.animation.curves import head_euler_from_rotation, head_rotation_from_euler
from workbench.animation.importers.errors import AnimationImportError

__all__ = [
    "LIVELINK_ANGLE_UNIT",
    "LIVELINK_EYE_COLUMNS",
    "LIVELINK_HEADER",
    "LIVELINK_HEAD_COLUMNS",
    "LIVELINK_SHAPE_COLUMNS",
    "livelink_fps",
    "livelink_head_angles",
    "livelink_head_rotation",
]


#: The 52 blendshape columns of a Live Link Face CSV, in the app's order and spelling.
#: The order is that of a recorded take's header (e.g. the header pinned byte for byte
#: in public Live Link Face tools): Unreal's ``EARFaceBlendShape`` order except that
#: ``JawRight`` comes before ``JawLeft`` and ``MouthRight`` before ``MouthLeft``.
LIVELINK_SHAPE_COLUMNS: tuple[str, ...] = (
    "EyeBlinkLeft", "EyeLookDownLeft", "EyeLookInLeft", "EyeLookOutLeft", "EyeLookUpLeft",
    "EyeSquintLeft", "EyeWideLeft",
    "EyeBlinkRight", "EyeLookDownRight", "EyeLookInRight", "EyeLookOutRight", "EyeLookUpRight",
    "EyeSquintRight", "EyeWideRight",
    "JawForward", "JawRight", "JawLeft", "JawOpen",
    "MouthClose", "MouthFunnel", "MouthPucker", "MouthRight", "MouthLeft",
    "MouthSmileLeft", "MouthSmileRight", "MouthFrownLeft", "MouthFrownRight",
    "MouthDimpleLeft", "MouthDimpleRight", "MouthStretchLeft", "MouthStretchRight",
    "MouthRollLower", "MouthRollUpper", "MouthShrugLower", "MouthShrugUpper",
    "MouthPressLeft", "MouthPressRight", "MouthLowerDownLeft", "MouthLowerDownRight",
    "MouthUpperUpLeft", "MouthUpperUpRight",
    "BrowDownLeft", "BrowDownRight", "BrowInnerUp", "BrowOuterUpLeft", "BrowOuterUpRight",
    "CheekPuff", "CheekSquintLeft", "CheekSquintRight", "NoseSneerLeft", "NoseSneerRight",
    "TongueOut",
)
#: Head rotation columns (normalised angles, see :data:`LIVELINK_ANGLE_UNIT`)
LIVELINK_HEAD_COLUMNS: tuple[str, ...] = ("HeadYaw", "HeadPitch", "HeadRoll")
#: Eye rotation columns (not read: the eyes are the ``eyeLook*`` shapes)
LIVELINK_EYE_COLUMNS: tuple[str, ...] = (
    "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll", "RightEyeYaw", "RightEyePitch", "RightEyeRoll",
)
#: The whole header row: 2 + 52 + 3 + 6 = 63 columns, ``BlendShapeCount`` = 61
LIVELINK_HEADER: tuple[str, ...] = (
    "Timecode", "BlendShapeCount", *LIVELINK_SHAPE_COLUMNS, *LIVELINK_HEAD_COLUMNS, *LIVELINK_EYE_COLUMNS,
)
#: Degrees per unit of the head/eye angle columns: Unreal's ARKit face support maps
#: the -180..180 degree range onto -1..1 (``ToBlendShapeMap``: ``HeadYaw = Yaw / 180``).
LIVELINK_ANGLE_UNIT = 180.0

_LLF_HEAD = tuple(c.lower() for c in LIVELINK_HEAD_COLUMNS)
_LLF_EYES = tuple(c.lower() for c in LIVELINK_EYE_COLUMNS)
_TIMECODE = re.compile(r"^(\d+):(\d\d):(\d\d)[:;](\d+)(?:\.(\d+))?$")


def livelink_head_rotation(
    yaw: float, pitch: float, roll: float, *, up_axis: str = "+y", front_axis: str = "+z"
) -> NDArray[np.float64]:
    """Unit quaternion ``(x, y, z, w)`` of Live Link Face ``HeadYaw/HeadPitch/HeadRoll`` values.

    The values are angles divided by :data:`LIVELINK_ANGLE_UNIT` (180 degrees,
    so -1..1; Unreal's ARKit face support writes ``Yaw / 180``). Signs and
    order are those of :func:`workbench.animation.curves.head_rotation_from_euler`
    about the model's own axes: positive yaw turns the face toward the
    subject's left, positive pitch nods it down, positive roll tilts the top of
    the head toward the subject's right. (That is what Unreal's conversion
    gives for ARKit's face frame — x the subject's left, y up, z out of the
    face — in its unmirrored mode, derived from the code rather than checked
    against a recording; the phone's orientation can flip signs in the app.)
    """
    u = LIVELINK_ANGLE_UNIT
    return head_rotation_from_euler(
        float(yaw) * u, float(pitch) * u, float(roll) * u, up_axis=up_axis, front_axis=front_axis
    )


def livelink_head_angles(
    rotation: ArrayLike, *, up_axis: str = "+y", front_axis: str = "+z"
) -> tuple[float, float, float]:
    """Inverse of :func:`livelink_head_rotation`: ``(HeadYaw, HeadPitch, HeadRoll)`` in -1..1."""
    yaw, pitch, roll = head_euler_from_rotation(rotation, up_axis=up_axis, front_axis=front_axis)
    u = LIVELINK_ANGLE_UNIT
    return yaw / u, pitch / u, roll / u


def _parse_timecode(text: str, src: str, row_label: str) -> tuple[int, float]:
    """``(whole seconds, frame number with its fraction)`` of ``HH:MM:SS:FF(.mmm)``."""
    m = _TIMECODE.match(text.strip())
    if not m:
        raise AnimationImportError(
            src, f"{row_label}, column 'Timecode': {text!r:.30} is not HH:MM:SS:FF(.fff)"
        )
    h, mi, sec, ff = (int(g) for g in m.groups()[:4])
    frac = float("0." + m.group(5)) if m.group(5) else 0.0
    return h * 3600 + mi * 60 + sec, ff + frac


def livelink_fps(seconds: ArrayLike, frames: ArrayLike) -> float:
    """The recording rate of Live Link Face timecodes, inferred as Epic's importer does.

    60 when a frame number reaches 30 (Epic's ``InferFrameRate``: above 30),
    30 when the rows cross a second boundary without one, else 60 (the app's
    default: rows within one second cannot tell 30 from 60).
    """
    f = np.asarray(frames, np.float64)
    s = np.asarray(seconds)
    if f.size and float(f.max()) >= 30.0:
        return 60.0
    if s.size and int(np.max(s)) != int(np.min(s)):
        return 30.0
    return 60.0
