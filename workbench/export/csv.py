"""CSV of per-frame blendshape weights (re-importable with :mod:`workbench.animation.importers`).

Two layouts:

``style="plain"`` (default)
    ``time,<shape>,<shape>,...`` — time in seconds, one row per frame, one
    column per model shape, values with 9 significant digits (float32 exact).
``style="livelink"``
    Epic's **Live Link Face** CSV, as the iPhone app writes a take and as
    Unreal's Live Link Face importer (``LiveLinkFaceImporter``: drop the .csv
    into the Content Browser → a Level Sequence for a MetaHuman / ARKit face)
    reads it:

    * header ``Timecode,BlendShapeCount,`` then the 52 ARKit columns in the
      app's order and spelling (``EyeBlinkLeft,EyeLookDownLeft,...,TongueOut``,
      :data:`~workbench.animation.importers.LIVELINK_SHAPE_COLUMNS`), then
      ``HeadYaw,HeadPitch,HeadRoll,LeftEyeYaw,LeftEyePitch,LeftEyeRoll,
      RightEyeYaw,RightEyePitch,RightEyeRoll`` — 63 columns;
      ``BlendShapeCount`` is 61 on every row.
    * ``Timecode`` is ``HH:MM:SS:FF.mmm``: the frame's time (timeline time 0 is
      ``00:00:00:00.000``), ``FF`` the frame within the second at the
      timeline's fps, ``mmm`` thousandths of a frame (Unreal reads
      ``FF.mmm`` as a fractional frame number). The fps must be a whole
      number (:class:`~workbench.export.ExportError` otherwise). Unreal's
      importer infers the rate from the frame numbers (60 when one exceeds 30,
      else 30): export at 30 or 60 fps for Unreal; another rate is written
      and noted.
    * weights: each ARKit column is the model's shape of that meaning on any
      rig (:mod:`workbench.arkit`): any spelling (``eyeBlink_L``); a shape
      split into halves (``browInnerUp_L``/``_R``) gives the **mean of its
      halves** (the importer gives the halves that weight back, so halves
      keyed alike round-trip exactly); one shape standing for a left/right
      pair (``mouthSmile``) fills both columns. A column without a shape is
      written as 0; shapes with no ARKit meaning are not written. Both are
      noted.
    * head: ``HeadYaw/HeadPitch/HeadRoll`` from the timeline's ``head_pose``
      track, normalised as the app does — the angle divided by 180 degrees,
      -1..1 (Unreal's ARKit face support writes ``Yaw / 180``) — about the
      model's own up/front axes (``model.metadata``): positive yaw turns the
      face toward the subject's left, positive pitch nods it down, positive
      roll tilts the top of the head toward the subject's right
      (:func:`~workbench.animation.importers.livelink_head_angles`). 0 without
      a head pose; the head translation has no column (noted when keyed).
    * eyes: the six eye angles are written as **0**. The app fills them from
      ARKit's eye transforms (not from the ``eyeLook*`` weights), which a
      blendshape rig does not have; the gaze is in the ``EyeLook*`` columns.

    :func:`workbench.animation.importers.read_weights_csv` reads the file
    back: the weights onto any rig, the head columns into the ``head_pose``
    track.

Rows hold what the model plays at each frame
(:meth:`workbench.export.encoding.MeshEncoding.weights`): unkeyed shapes at
their current weight, keyed weights clamped to the slider range, muted shapes
0. A CSV carries weights only: the editing layers (regions, handles, paint,
wrinkles) cannot go into it; every active one is reported as ``"omitted"``
in the returned :class:`~workbench.export.ExportResult` and logged as a
warning — export a mesh format (glTF, USD, PC2/MDD) to keep them. What the
Live Link layout leaves out or changes is in the result's
:attr:`CsvExportResult.notes` and logged on the ``workbench.export`` logger.
Written with the csv module into a temporary file, then renamed.
"""

from __future__ import annotations

import csv
import logging
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from workbench.animation.importers import (
    LIVELINK_HEADER,
    LIVELINK_SHAPE_COLUMNS,
    livelink_head_angles,
)
from workbench.animation.tracks import Timeline
from workbench.arkit import canonical_arkit_name, split_half_of
from workbench.export.base import ExportError, ExportResult, LayerReport, atomic_path
from workbench.export.encoding import MeshEncoding

if TYPE_CHECKING:
    from workbench.model import FaceModel

__all__ = ["CsvExportResult", "livelink_weight_map", "timecode", "write"]

logger = logging.getLogger("workbench.export")

_ARKIT_COLUMNS = [canonical_arkit_name(c) for c in LIVELINK_SHAPE_COLUMNS]
_COLUMN_OF = {c: j for j, c in enumerate(_ARKIT_COLUMNS) if c is not None}
_BLENDSHAPE_COUNT = len(LIVELINK_HEADER) - 2  # 61: 52 shapes + 3 head + 6 eye angles


class CsvExportResult(ExportResult):
    """:class:`~workbench.export.ExportResult` plus :attr:`notes`: sentences on what the layout changed."""

    def __init__(
        self,
        paths: list[Path] | tuple[Path, ...] = (),
        layers: tuple[LayerReport, ...] | list[LayerReport] = (),
        notes: Sequence[str] = (),
    ) -> None:
        super().__init__(paths, layers)
        self.notes: tuple[str, ...] = tuple(notes)


def timecode(t: float, fps: float) -> str:
    """``HH:MM:SS:FF.mmm`` for ``t`` seconds at ``fps``: frame ``FF`` of the second, ``mmm``/1000 of a frame.

    Raises
    ------
    ExportError
        ``fps`` is not a whole number of frames per second, or ``t`` < 0.
    """
    per_sec = round(fps) if math.isfinite(fps) else 0
    if per_sec < 1 or abs(per_sec - fps) > 1e-9:
        raise ExportError(
            f"Live Link Face timecodes count whole frames per second; the timeline's fps is {fps:g}: "
            f"export at a whole rate (30 or 60 for Unreal), e.g. fps=30 (--fps 30)"
        )
    if not t >= -1e-9:
        raise ExportError(f"Live Link Face timecodes cannot be negative: frame at {t:g} s; start the timeline at 0 or later")
    milli = max(round(t * per_sec * 1000.0), 0)  # thousandths of a frame
    frames, mmm = divmod(milli, 1000)
    secs, ff = divmod(frames, per_sec)
    h, rem = divmod(secs, 3600)
    m, s = divmod(rem, 60)
    return f"{h:02d}:{m:02d}:{s:02d}:{ff:02d}.{mmm:03d}"


def livelink_weight_map(shape_names: Sequence[str]) -> tuple[NDArray[np.float64], list[tuple[int, str]]]:
    """How a rig's shape weights make the 52 Live Link Face columns (see the module docstring).

    Parameters
    ----------
    shape_names : sequence of str
        The rig's shapes.

    Returns
    -------
    M : (k, 52) float
        Column weights = shape weights @ M, columns in
        :data:`~workbench.animation.importers.LIVELINK_SHAPE_COLUMNS` order.
    notes : list of (int, str)
        ``(logging level, sentence)``: columns without a shape (written as 0),
        shapes not written, split halves and left/right pairs.
    """
    names = list(shape_names)
    M = np.zeros((len(names), len(LIVELINK_SHAPE_COLUMNS)))
    owner: dict[str, str] = {}  # ARKit name -> the shape written to its column
    halves: dict[str, list[int]] = {}
    pairs: dict[str, int] = {}
    skipped: list[str] = []
    duplicate: list[str] = []
    for i, n in enumerate(names):
        c = canonical_arkit_name(n)
        if c is not None:
            if c in owner:
                duplicate.append(f"{n!r} (column {c!r} is written from {owner[c]!r})")
            else:
                owner[c] = n
                M[i, _COLUMN_OF[c]] = 1.0
            continue
        h = split_half_of(n)
        if h is not None:
            halves.setdefault(h[0], []).append(i)
            continue
        left, right = canonical_arkit_name(n + "_Left"), canonical_arkit_name(n + "_Right")
        if left is not None and right is not None:
            stem = left.removesuffix("Left")
            if stem in pairs:
                duplicate.append(f"{n!r} (the pair {stem}Left/Right is written from {names[pairs[stem]]!r})")
            else:
                pairs[stem] = i
            continue
        skipped.append(n)
    notes: list[tuple[int, str]] = []
    for whole, idx in halves.items():
        if whole in owner:
            duplicate.extend(f"{names[i]!r} (column {whole!r} is written from {owner[whole]!r})" for i in idx)
            continue
        owner[whole] = names[idx[0]]
        M[idx, _COLUMN_OF[whole]] = 1.0 / len(idx)
        notes.append((logging.INFO, f"{whole} is the mean of the split halves {[names[i] for i in idx]}"))
    for stem, i in pairs.items():
        cols = [f"{stem}{side}" for side in ("Left", "Right") if f"{stem}{side}" not in owner]
        for c in cols:
            owner[c] = names[i]
            M[i, _COLUMN_OF[c]] = 1.0
        if cols:
            notes.append((logging.INFO, f"{names[i]!r} fills both {stem}Left and {stem}Right"))
    missing = [c for c in _ARKIT_COLUMNS if c is not None and c not in owner]
    if missing:
        notes.append((logging.WARNING, f"the rig has no shape for ARKit {missing}: written as 0"))
    if skipped:
        notes.append((logging.WARNING, f"shapes with no ARKit meaning are not written: {skipped}"))
    if duplicate:
        notes.append((logging.WARNING, f"not written, another shape has the same ARKit meaning: {duplicate}"))
    return M, notes


def _fixed(x: float) -> str:
    s = f"{x:.9f}"
    return "0.000000000" if s == "-0.000000000" else s


def _livelink_rows(
    model: FaceModel, timeline: Timeline, times: NDArray[np.float64], W: NDArray[np.float64]
) -> tuple[list[list[str]], list[tuple[int, str]]]:
    fps = timeline.fps
    tcs = [timecode(float(t), fps) for t in times]  # raises on a non-whole fps before anything is written
    M, notes = livelink_weight_map(model.shape_names)
    A = W @ M
    if A.size and (float(A.min()) < 0.0 or float(A.max()) > 1.0):
        notes.append((logging.WARNING, f"weights outside 0..1 are written as they are "
                                       f"(min {float(A.min()):.3g}, max {float(A.max()):.3g}); ARKit weights are 0..1"))
    head = np.zeros((times.size, 3))
    hp = timeline.head_pose
    if hp is not None:
        md = model.metadata
        P = hp.sample(times)
        head = np.array([livelink_head_angles(q, up_axis=md.up_axis, front_axis=md.front_axis) for q in P[:, 3:]])
        if np.any(P[:, :3] != 0.0):
            notes.append((logging.WARNING, "the head translation is not written: Live Link Face has head rotation only"))
    per_sec = round(fps)
    if per_sec not in (30, 60):
        notes.append((logging.WARNING, f"{per_sec} fps: Unreal's Live Link Face importer assumes 30 or 60 fps "
                                       f"(from the frame numbers) and will play this file at the wrong speed"))
    elif per_sec == 60 and times.size and max(float(tc.rsplit(":", 1)[1]) for tc in tcs) <= 30.0:
        notes.append((logging.WARNING, "60 fps but no frame number above 30 (a take under half a second): "
                                       "Unreal's importer will read it as 30 fps"))
    rows = []
    eyes = ["0.000000000"] * 6
    for tc, a, h in zip(tcs, A, head, strict=True):
        rows.append([tc, str(_BLENDSHAPE_COUNT), *(_fixed(x) for x in a), *(_fixed(x) for x in h), *eyes])
    return rows, notes


def write(
    model: FaceModel, timeline: Timeline, path: Path, *, bake: bool = True, style: str = "plain"
) -> CsvExportResult:
    """Write the weights of every shape at every frame (see module docstring)."""
    if style not in ("plain", "livelink"):
        raise ExportError(f"CSV style must be 'plain' or 'livelink', got {style!r}")
    enc = MeshEncoding(model, timeline)
    times = timeline.frame_times()
    W = enc.weights(times)
    # registered (non-built-in) layers are not evaluated here: reported as omitted
    layers = [
        LayerReport(r.name, "omitted", f"a CSV holds weights only; {r.detail}")
        if r.encoding in ("linear", "baked") else r
        for r in enc.layers
    ]
    notes: list[tuple[int, str]] = []
    if style == "plain":
        header = ["time", *model.shape_names]
        rows = [[f"{t:.9g}", *(f"{x:.9g}" for x in row)] for t, row in zip(times, W, strict=True)]
    else:
        header = list(LIVELINK_HEADER)
        rows, notes = _livelink_rows(model, timeline, times, W)
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    for level, text in notes:
        logger.log(level, "%s: %s", Path(path).name, text)
    return CsvExportResult([path], layers, [text for _, text in notes])
