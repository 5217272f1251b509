"""Import animation: per-frame ARKit weight CSVs and glTF weight animations → a Timeline.

Supported inputs
----------------
* **Live Link Face CSV** (Epic's iPhone app): header
  ``Timecode,BlendShapeCount,EyeBlinkLeft,...`` (52 ARKit columns, then
  ``HeadYaw``, ``HeadPitch``, ``HeadRoll``, ``LeftEyeYaw``... which are not
  shapes and are skipped). ``Timecode`` is SMPTE-like ``HH:MM:SS:FF.fff``
  (frame number plus a fraction of a frame) at the recording rate (``fps``,
  60 by default); times are made relative to the first row.
* **Plain weight CSV** (what :mod:`workbench.export.csv` writes; also the common
  "time + one column per shape" layout): a first column named ``time``,
  ``Time``, ``seconds`` (seconds) or ``time_ms``/``timestamp_ms`` (milliseconds),
  then one column per shape.
* **Face Cap text** (Bannaflak's iOS app, ``.txt``/``.csv``): a ``bs,<names>``
  line and ``k,<milliseconds>,<3 head position>,<3 head rotation>,
  <4 eye angles>,<weights>`` lines; ``info`` lines are ignored. (Layout as
  documented by the app; not checked against a recording here.)
* **glTF/GLB weight animations**: every ``weights`` channel of an animation;
  ``LINEAR`` → linear keys, ``STEP`` → step keys, ``CUBICSPLINE`` → Bézier keys
  with user tangents (exact: glTF's Hermite tangents are our slopes).

Column names are matched to the model's shapes exactly first, then by ARKit
meaning (:func:`workbench.arkit.canonical_arkit_name`, so ``EyeBlinkLeft``,
``eyeBlink_L`` and ``eyeBlinkLeft`` agree). Every problem raises
:class:`AnimationImportError` naming the file, the row/line and the column.

CSV rows become one linear key per frame; ``tolerance`` > 0 removes keys that
linear interpolation of the kept ones reproduces within ``tolerance``
(Ramer–Douglas–Peucker on each weight curve, vertical error), so the result
differs from every input sample by at most ``tolerance``.

Hand-written because the csv module gives strings only, and the glTF decoding
reuses the checked accessor reader of :mod:`workbench.io.gltf` (pygltflib has
no accessor decoding).
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.animation.curves import Interpolation, Key, Track, TrackError, weight_track_name
from workbench.animation.tracks import Timeline
from workbench.arkit import canonical_arkit_name

__all__ = [
    "AnimationImportError",
    "map_shape_names",
    "read_animation",
    "read_gltf_animation",
    "read_weights_csv",
    "reduce_keys",
]

#: Live Link Face columns that are not blendshapes (head and eye rotations)
_LLF_NON_SHAPES = {
    "headyaw",
    "headpitch",
    "headroll",
    "lefteyeyaw",
    "lefteyepitch",
    "lefteyeroll",
    "righteyeyaw",
    "righteyepitch",
    "righteyeroll",
}
_TIME_SECONDS = ("time", "seconds", "time_s", "t")
_TIME_MS = ("time_ms", "timestamp_ms", "timestamp", "milliseconds")
_TIMECODE = re.compile(r"^(\d+):(\d\d):(\d\d)[:;](\d+)(?:\.(\d+))?$")


class AnimationImportError(ValueError):
    """An animation file that cannot be turned into keys; the message names file, row and column."""

    def __init__(self, source: str | Path, message: str) -> None:
        self.source = str(source)
        self.detail = message
        super().__init__(f"{Path(self.source).name}: {message}")


# -------------------------------------------------------------------- name mapping
def map_shape_names(
    columns: Sequence[str], shape_names: Sequence[str], source: str | Path = "<columns>"
) -> dict[str, str | None]:
    """Map file column/target names to model shape names.

    Exact matches win; otherwise two names match if they have the same
    canonical ARKit name. Returns ``{column: shape or None}``.

    Raises
    ------
    AnimationImportError
        If two columns map to the same shape.
    """
    by_arkit: dict[str, str] = {}
    for s in shape_names:
        c = canonical_arkit_name(s)
        if c is not None:
            by_arkit.setdefault(c, s)
    exact = set(shape_names)
    out: dict[str, str | None] = {}
    used: dict[str, str] = {}
    for col in columns:
        target: str | None = None
        if col in exact:
            target = col
        else:
            c = canonical_arkit_name(col)
            if c is not None:
                target = by_arkit.get(c)
        if target is not None:
            if target in used:
                raise AnimationImportError(
                    source, f"columns {used[target]!r} and {col!r} both map to shape {target!r}"
                )
            used[target] = col
        out[col] = target
    return out


# -------------------------------------------------------------------- key reduction
def reduce_keys(times: ArrayLike, values: ArrayLike, tolerance: float) -> NDArray[np.intp]:
    """Indices of the samples to keep so linear interpolation stays within ``tolerance``.

    Parameters
    ----------
    times : (F,) float
        Strictly increasing.
    values : (F,) float
    tolerance : float
        Maximum absolute difference, at every input sample, between the input
        and the piecewise-linear curve through the kept samples (>= 0).

    Returns
    -------
    (K,) int
        Sorted indices, always including the first and last sample.
    """
    t = np.asarray(times, np.float64)
    v = np.asarray(values, np.float64)
    n = t.size
    if n <= 2 or tolerance < 0:
        return np.arange(n)
    keep = np.zeros(n, bool)
    keep[0] = keep[-1] = True
    stack = [(0, n - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        seg_t = t[a + 1 : b]
        line = v[a] + (v[b] - v[a]) * (seg_t - t[a]) / (t[b] - t[a])
        err = np.abs(v[a + 1 : b] - line)
        i = int(np.argmax(err))
        if err[i] > tolerance:
            m = a + 1 + i
            keep[m] = True
            stack.append((a, m))
            stack.append((m, b))
    return np.flatnonzero(keep)


def _linear_track(name: str, times: NDArray[np.float64], values: NDArray[np.float64]) -> Track:
    return Track(
        name,
        tuple(Key(float(t), float(v), "linear") for t, v in zip(times, values, strict=True)),
    )


def timeline_from_samples(
    times: ArrayLike,
    weights: ArrayLike,
    shape_names: Sequence[str],
    *,
    fps: float = 30.0,
    tolerance: float = 0.0,
) -> Timeline:
    """A timeline with one linear key per sample (optionally reduced) for every shape.

    Parameters
    ----------
    times : (F,) float
        Strictly increasing seconds.
    weights : (F, k) float
        Finite weights, one column per name in ``shape_names``.
    shape_names : sequence of str
        Model shape names (length k).
    fps : float
        Timeline frame rate.
    tolerance : float
        Key-reduction tolerance (0 keeps every sample).
    """
    t = np.asarray(times, np.float64).reshape(-1)
    W = np.asarray(weights, np.float64).reshape(t.size, -1)
    tracks = {}
    for j, s in enumerate(shape_names):
        idx = reduce_keys(t, W[:, j], tolerance) if tolerance > 0 else np.arange(t.size)
        name = weight_track_name(s)
        tracks[name] = _linear_track(name, t[idx], W[idx, j])
    return Timeline(fps=fps, start=float(t[0]), end=float(t[-1]), tracks=tracks)


# ----------------------------------------------------------------------- CSV
def _parse_float(text: str, src: str, row_label: str, col: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise AnimationImportError(
            src, f"{row_label}, column {col!r}: {text!r:.30} is not a number"
        ) from None
    if not math.isfinite(x):
        raise AnimationImportError(src, f"{row_label}, column {col!r}: value is {text.strip()} (NaN/inf)")
    return x


def _parse_timecode(text: str, fps: float, src: str, row_label: str) -> float:
    m = _TIMECODE.match(text.strip())
    if not m:
        raise AnimationImportError(
            src, f"{row_label}, column 'Timecode': {text!r:.30} is not HH:MM:SS:FF(.fff)"
        )
    h, mi, s, ff = (int(g) for g in m.groups()[:4])
    frac = float("0." + m.group(5)) if m.group(5) else 0.0
    return h * 3600.0 + mi * 60.0 + s + (ff + frac) / fps


def _check_times(times: NDArray[np.float64], labels: Sequence[str], src: str) -> None:
    bad = np.flatnonzero(np.diff(times) <= 0)
    if bad.size:
        i = int(bad[0])
        raise AnimationImportError(
            src,
            f"{labels[i + 1]}: time {times[i + 1]:.6g} s does not come after {labels[i]} "
            f"({times[i]:.6g} s); times must be strictly increasing",
        )


def _resolve_columns(
    columns: Sequence[str],
    shape_names: Sequence[str],
    src: str,
    on_unknown: str,
    skip: Iterable[str] = (),
) -> list[tuple[int, str]]:
    """(column index, shape name) pairs; unknown columns raise unless ``on_unknown="ignore"``."""
    skip_l = {s.lower() for s in skip}
    mapping = map_shape_names(columns, shape_names, src)
    out: list[tuple[int, str]] = []
    unknown: list[str] = []
    for i, col in enumerate(columns):
        if col.strip().lower() in skip_l or not col.strip():
            continue
        target = mapping[col]
        if target is None:
            unknown.append(col)
        else:
            out.append((i, target))
    if unknown and on_unknown != "ignore":
        raise AnimationImportError(
            src,
            f"unknown shape names in columns {unknown[:10]}{'...' if len(unknown) > 10 else ''} "
            f"(the model has no shape of that name or ARKit meaning; pass on_unknown='ignore' "
            f"to skip them)",
        )
    if not out:
        raise AnimationImportError(src, "no column matches a shape of the model")
    return out


def read_weights_csv(
    path: str | Path,
    shape_names: Sequence[str],
    *,
    fps: float | None = None,
    tolerance: float = 0.0,
    on_unknown: str = "error",
) -> Timeline:
    """Read a Live Link Face / plain / Face Cap weight CSV into a timeline of linear keys.

    Parameters
    ----------
    path : str or Path
    shape_names : sequence of str
        The model's shape names (``model.shape_names``); columns are mapped to
        them (exact, else ARKit meaning).
    fps : float, optional
        Frame rate of Live Link Face timecodes (default 60) and of the returned
        timeline (default: 60 for Live Link Face, else estimated from the median
        sample spacing, else 30).
    tolerance : float
        Key reduction (see :func:`reduce_keys`); 0 keeps one key per row.
    on_unknown : {"error", "ignore"}
        What to do with columns that match no shape.

    Returns
    -------
    Timeline
        Tracks ``"weights/<shape>"``; range = first..last time (first row at 0
        for Live Link Face timecodes and Face Cap milliseconds).

    Raises
    ------
    AnimationImportError
        Unknown columns, non-numeric/NaN values, non-increasing times, ragged
        rows — each naming the line and column.
    """
    p = Path(path)
    src = str(p)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise AnimationImportError(src, f"not UTF-8 text (byte {exc.start})") from None
    rows = [(i + 1, r) for i, r in enumerate(csv.reader(text.splitlines())) if any(c.strip() for c in r)]
    if not rows:
        raise AnimationImportError(src, "empty file")
    first = [c.strip() for c in rows[0][1]]
    if first and first[0].lower() in ("bs", "info", "k"):
        return _read_facecap(rows, shape_names, src, fps, tolerance, on_unknown)
    header = first
    lower = [h.lower() for h in header]
    if "timecode" in lower:
        rate = 60.0 if fps is None else float(fps)
        tcol = lower.index("timecode")
        skip = ["timecode", "blendshapecount", *_LLF_NON_SHAPES]
        kind = "timecode"
    elif lower[0] in _TIME_SECONDS or lower[0] in _TIME_MS:
        tcol = 0
        skip = [header[0]]
        kind = "ms" if lower[0] in _TIME_MS else "s"
        rate = 0.0
    else:
        raise AnimationImportError(
            src,
            f"line {rows[0][0]}: header must start with a time column ('time' in seconds, "
            f"'time_ms') or contain 'Timecode' (Live Link Face), got {header[:3]}",
        )
    cols = _resolve_columns(header, shape_names, src, on_unknown, skip)
    n = len(rows) - 1
    if n < 1:
        raise AnimationImportError(src, "header but no data rows")
    times = np.empty(n)
    W = np.empty((n, len(cols)))
    labels = []
    for r, (lineno, row) in enumerate(rows[1:]):
        label = f"line {lineno}"
        labels.append(label)
        if len(row) != len(header):
            raise AnimationImportError(
                src, f"{label}: has {len(row)} fields, the header has {len(header)}"
            )
        if kind == "timecode":
            times[r] = _parse_timecode(row[tcol], rate, src, label)
        else:
            times[r] = _parse_float(row[tcol], src, label, header[tcol])
        for j, (ci, _) in enumerate(cols):
            W[r, j] = _parse_float(row[ci], src, label, header[ci])
    if kind == "ms":
        times = times / 1000.0
    if kind == "timecode":
        times = times - times[0]
    _check_times(times, labels, src)
    if fps is None:
        fps = rate if kind == "timecode" else _estimate_fps(times)
    return timeline_from_samples(
        times, W, [s for _, s in cols], fps=float(fps), tolerance=tolerance
    )


def _estimate_fps(times: NDArray[np.float64]) -> float:
    if times.size < 2:
        return 30.0
    dt = float(np.median(np.diff(times)))
    return round(1.0 / dt, 3) if dt > 0 else 30.0


def _read_facecap(
    rows: list[tuple[int, list[str]]],
    shape_names: Sequence[str],
    src: str,
    fps: float | None,
    tolerance: float,
    on_unknown: str,
) -> Timeline:
    names: list[str] | None = None
    times: list[float] = []
    values: list[list[float]] = []
    labels: list[str] = []
    n_pre = 12  # "k", ms, head position (3), head rotation (3), eye angles (4)
    for lineno, row in rows:
        tag = row[0].strip().lower()
        label = f"line {lineno}"
        if tag == "bs":
            names = [c.strip() for c in row[1:]]
        elif tag == "k":
            if names is None:
                raise AnimationImportError(src, f"{label}: 'k' line before the 'bs' names line")
            if len(row) != n_pre + len(names):
                raise AnimationImportError(
                    src,
                    f"{label}: has {len(row)} fields, expected {n_pre + len(names)} "
                    f"(k, ms, 10 head/eye values, {len(names)} weights)",
                )
            times.append(_parse_float(row[1], src, label, "time (ms)") / 1000.0)
            values.append(
                [_parse_float(row[n_pre + j], src, label, names[j]) for j in range(len(names))]
            )
            labels.append(label)
    if names is None or not times:
        raise AnimationImportError(src, "Face Cap file without 'bs' names and 'k' key lines")
    cols = _resolve_columns(names, shape_names, src, on_unknown)
    t = np.array(times)
    t = t - t[0]
    _check_times(t, labels, src)
    W = np.array(values)[:, [ci for ci, _ in cols]]
    return timeline_from_samples(
        t, W, [s for _, s in cols], fps=float(fps or _estimate_fps(t)), tolerance=tolerance
    )


# ----------------------------------------------------------------------- glTF
def read_gltf_animation(
    path: str | Path,
    shape_names: Sequence[str],
    *,
    animation: int | str | None = None,
    fps: float = 30.0,
    on_unknown: str = "error",
) -> Timeline:
    """Read the morph-weight channels of a glTF animation into keys.

    Parameters
    ----------
    path : str or Path
        .glb or .gltf.
    shape_names : sequence of str
        The model's shape names; targets are matched by ``mesh.extras.targetNames``
        (exact, else ARKit meaning). Targets named ``handle:...`` (the handle
        layer written by :mod:`workbench.export.gltf`) are skipped.
    animation : int or str, optional
        Animation index or name (default: the first one with a weights channel).
    fps : float
        Frame rate of the returned timeline.
    on_unknown : {"error", "ignore"}
        What to do with targets that match no shape.

    Raises
    ------
    AnimationImportError
        No weights animation, unnamed targets, unknown names, NaN values,
        non-increasing times, output counts that do not match.
    """
    from workbench.geometry.mesh_checks import MeshFormatError
    from workbench.io.gltf import _GLB_MAGIC, _Gltf, _parse_json, _split_glb

    p = Path(path)
    src = str(p)
    try:
        data = p.read_bytes()
        if p.suffix.lower() == ".glb" or data[:4] == _GLB_MAGIC:
            json_raw, bin_chunk = _split_glb(data, src)
        else:
            json_raw, bin_chunk = data, None
        g = _Gltf(_parse_json(json_raw, src), src, bin_chunk, p.parent)
        return _gltf_timeline(g, src, shape_names, animation, fps, on_unknown)
    except MeshFormatError as exc:
        raise AnimationImportError(src, exc.detail) from None


def _gltf_timeline(
    g: Any,
    src: str,
    shape_names: Sequence[str],
    animation: int | str | None,
    fps: float,
    on_unknown: str,
) -> Timeline:
    anims = g.array("animations")
    if not anims:
        raise AnimationImportError(src, "the file has no animations")
    ai: int | None = None
    if isinstance(animation, int):
        ai = animation
    elif isinstance(animation, str):
        names = [a.get("name") if isinstance(a, dict) else None for a in anims]
        if animation not in names:
            raise AnimationImportError(src, f"no animation named {animation!r}; names: {names}")
        ai = names.index(animation)
    else:
        for i, a in enumerate(anims):
            chans = a.get("channels", []) if isinstance(a, dict) else []
            if any(isinstance(c, dict) and (c.get("target") or {}).get("path") == "weights" for c in chans):
                ai = i
                break
        if ai is None:
            raise AnimationImportError(src, "no animation has a 'weights' channel")
    anim = g.item("animations", ai, "animations")
    afield = f"animations[{ai}]"
    samplers = anim.get("samplers", [])
    tracks: dict[str, Track] = {}
    found = False
    for c, ch in enumerate(anim.get("channels", [])):
        cfield = f"{afield}.channels[{c}]"
        target = ch.get("target") if isinstance(ch, dict) else None
        if not isinstance(target, dict) or target.get("path") != "weights":
            continue
        found = True
        node = g.item("nodes", target.get("node"), f"{cfield}.target.node")
        mesh = g.item("meshes", node.get("mesh"), f"{cfield} node.mesh")
        extras = mesh.get("extras")
        tnames = extras.get("targetNames") if isinstance(extras, dict) else None
        if not isinstance(tnames, list) or not all(isinstance(s, str) for s in tnames):
            raise AnimationImportError(
                src, f"{cfield}: the animated mesh has no extras.targetNames; cannot name its targets"
            )
        si = ch.get("sampler")
        if not isinstance(si, int) or not 0 <= si < len(samplers):
            raise AnimationImportError(src, f"{cfield}.sampler: {si!r} is not a sampler index")
        s = samplers[si]
        sfield = f"{afield}.samplers[{si}]"
        interp = s.get("interpolation", "LINEAR")
        if interp not in ("LINEAR", "STEP", "CUBICSPLINE"):
            raise AnimationImportError(src, f"{sfield}.interpolation: unknown {interp!r}")
        T = g.accessor(s.get("input"), f"{sfield}.input", types=("SCALAR",))[:, 0]
        out = g.accessor(s.get("output"), f"{sfield}.output", types=("SCALAR",))[:, 0]
        nk, nt = T.size, len(tnames)
        per = 3 if interp == "CUBICSPLINE" else 1
        if out.size != nk * nt * per:
            raise AnimationImportError(
                src,
                f"{sfield}.output: has {out.size} values, expected {nk} keys x {nt} targets"
                f"{' x 3' if per == 3 else ''} = {nk * nt * per}",
            )
        if not np.isfinite(T).all() or not np.isfinite(out).all():
            raise AnimationImportError(src, f"{sfield}: NaN/inf in input times or output weights")
        bad = np.flatnonzero(np.diff(T) <= 0)
        if bad.size:
            i = int(bad[0])
            raise AnimationImportError(
                src,
                f"{sfield}.input: key {i + 1} time {T[i + 1]:.6g} s does not come after key {i} "
                f"({T[i]:.6g} s); times must be strictly increasing",
            )
        out = out.reshape(nk, per, nt)
        cols = [n for n in tnames if not n.startswith("handle:")]
        mapping = _resolve_columns(cols, shape_names, src, on_unknown)
        mode: Interpolation = "step" if interp == "STEP" else "linear"
        for ci, shape in mapping:
            t_idx = tnames.index(cols[ci])
            if per == 3:
                keys = tuple(
                    Key(
                        float(T[k]),
                        float(out[k, 1, t_idx]),
                        "bezier",
                        float(out[k, 0, t_idx]),
                        float(out[k, 2, t_idx]),
                        "user",
                    )
                    for k in range(nk)
                )
            else:
                keys = tuple(Key(float(T[k]), float(out[k, 0, t_idx]), mode) for k in range(nk))
            name = weight_track_name(shape)
            try:
                tracks[name] = Track(name, keys)
            except TrackError as exc:
                raise AnimationImportError(src, f"{sfield}: {exc}") from None
    if not found:
        raise AnimationImportError(src, f"{afield} has no 'weights' channel")
    tl = Timeline(fps=fps, tracks=tracks)
    return tl.fit_range()


def read_animation(path: str | Path, shape_names: Sequence[str], **kw: Any) -> Timeline:
    """Dispatch by suffix: .glb/.gltf → :func:`read_gltf_animation`, else :func:`read_weights_csv`."""
    p = Path(path)
    if p.suffix.lower() in (".glb", ".gltf"):
        return read_gltf_animation(p, shape_names, **kw)
    return read_weights_csv(p, shape_names, **kw)
