"""Capture inputs: markers/landmarks, marker→vertex maps, point clouds and depth frames (issue 17, item 1).

Everything a reader returns is in **metres**, with the unit the data were in
recorded (``.units``); :func:`to_model_units` converts to a model's unit
(``model.metadata.units``). Every problem with a file raises
:class:`CaptureInputError` (a :class:`~workbench.geometry.mesh_checks.MeshFormatError`,
so a ``ValueError``) whose message names the file, the line and/or frame, and
the column or field, and says what was expected. A reader returns everything
or raises: nothing is half-loaded.

The formats, and the module that reads and documents each
---------------------------------------------------------
* Markers and landmarks → :class:`~workbench.io.markers.MarkerSequence`
  (:mod:`.markers`): :func:`read_markers` picks the reader by suffix —
  ``.c3d`` (ezc3d; ``POINT:UNITS``), ``.csv`` / ``.txt``, ``.npy`` (T, m, 3),
  ``.npz`` (``positions``, optional ``names``, ``fps``, ``units``,
  ``first_frame``); :func:`as_marker_sequence` wraps an in-memory array.
* Marker CSV (:mod:`.marker_csv`): :func:`read_marker_csv` — a flat layout
  (``<name>_x`` or ``<name>.X`` columns, optional ``frame`` and ``time``) or
  the Vicon Nexus "Trajectories" layout; ``# units: mm`` / ``# fps: 120``
  comments; an empty cell or ``NaN`` is an occluded marker.
* Marker → vertex maps (:mod:`.vertex_map`): :func:`read_vertex_map` —
  ``marker,vertex`` CSV, JSON, a dict or an (m,) integer array.
* Point clouds → :class:`PointCloudSequence` (:mod:`.clouds`):
  :func:`read_point_clouds` (:mod:`.cloud_files`) — a folder of ``.ply``
  files (sorted naturally), one ``.ply``, or an ``.npz`` in one of three
  layouts.
* Depth frames (:mod:`.depth`): :func:`read_depth_frames` — a folder of
  16-bit PNGs with :func:`read_intrinsics` (:mod:`.intrinsics`:
  :class:`CameraIntrinsics` from ``fx, fy, cx, cy``, Open3D's
  ``intrinsic_matrix`` or ``K``); :func:`depth_to_points` back-projects one
  image (OpenCV pinhole convention; returned +y up, +z toward the camera).

Units and frame rates (:mod:`.units`): ``units=`` wins, else the unit the
file states; a file stating none is an error. With ``check_units=True`` data
that are not face-sized in their unit (:data:`MARKER_SPAN`; depth:
:data:`DEPTH_RANGE`) are refused, naming the unit that would fit. ``fps=``
wins, else the file's, else 30 with a warning. :mod:`.errors` holds
:class:`CaptureInputError`; :mod:`.npz` and :mod:`.csv_text` the low-level
file reading the readers share.
"""

from workbench.capture.inputs.cloud_files import read_point_clouds
from workbench.capture.inputs.clouds import PointCloudSequence
from workbench.capture.inputs.depth import DEPTH_RANGE, depth_to_points, read_depth_frames
from workbench.capture.inputs.errors import CaptureInputError
from workbench.capture.inputs.intrinsics import CameraIntrinsics, read_intrinsics
from workbench.capture.inputs.marker_csv import read_marker_csv
from workbench.capture.inputs.markers import as_marker_sequence, read_markers
from workbench.capture.inputs.units import DEFAULT_FPS as DEFAULT_FPS
from workbench.capture.inputs.units import MARKER_SPAN, metres_per_unit, to_model_units
from workbench.capture.inputs.units import log as log
from workbench.capture.inputs.vertex_map import read_vertex_map
from workbench.io.markers import MarkerSequence

__all__ = [
    "DEPTH_RANGE",
    "MARKER_SPAN",
    "CameraIntrinsics",
    "CaptureInputError",
    "MarkerSequence",
    "PointCloudSequence",
    "as_marker_sequence",
    "depth_to_points",
    "metres_per_unit",
    "read_depth_frames",
    "read_intrinsics",
    "read_marker_csv",
    "read_markers",
    "read_point_clouds",
    "read_vertex_map",
    "to_model_units",
]
