"""C3D motion-capture files → :class:`~workbench.io.markers.MarkerSequence` (markers, not a face).

Read with ezc3d (PyPI ``ezc3d``, the C3D reader/writer used in biomechanics),
after a checked walk of the file's structure in Python: ezc3d is C++ and takes
the header and parameter section at their word, so a truncated or damaged file
can crash the process (a truncated file did, in a fuzz run) or load garbage.
:func:`check_c3d` therefore verifies, before ezc3d sees the file:

* the header (parameter block pointer, the 0x50 key, point/analog counts,
  frame range, scale, data start, frame rate);
* the parameter section: processor type (Intel, DEC or MIPS), every group and
  parameter record inside the section (names, offsets, types, dimensions), and
  the ``POINT`` parameters the markers need (``USED``, ``LABELS``, ``UNITS``,
  ``RATE``, ``SCALE``, ``DATA_START``, ``FRAMES``), consistent with the header;
* that the data section holds every frame's points and analog samples.

What :func:`read_markers` returns: labels (``POINT:LABELS``, then ``LABELS2``...),
positions converted to metres from ``POINT:UNITS`` (mm, cm, dm, m, in), NaN
where a marker is missing (residual < 0, ezc3d's NaN), ``POINT:RATE`` frames
per second. Every problem raises :class:`MeshFormatError` naming the file and
the header word or parameter.
"""

from __future__ import annotations

import logging
import math
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.markers import MarkerSequence

__all__ = ["UNITS_TO_METRES", "C3dLayout", "check_c3d", "read_markers"]

log = logging.getLogger("workbench.io")

#: POINT:UNITS spelling -> metres per unit
UNITS_TO_METRES = {
    "mm": 0.001, "millimeters": 0.001, "millimetres": 0.001,
    "cm": 0.01, "centimeters": 0.01, "centimetres": 0.01,
    "dm": 0.1,
    "m": 1.0, "meters": 1.0, "metres": 1.0,
    "in": 0.0254, "inch": 0.0254, "inches": 0.0254,
}
_PROCESSORS = {84: "Intel", 85: "DEC", 86: "MIPS"}
_TYPES = {-1: 1, 1: 1, 2: 2, 4: 4}


@dataclass
class C3dLayout:
    """What :func:`check_c3d` found: counts, the POINT parameters, the processor."""

    processor: str
    n_points: int
    analog_per_frame: int
    first_frame: int
    n_frames: int
    scale: float
    rate: float
    data_start: int
    params: dict[str, dict[str, Any]] = field(default_factory=dict)


def _dec_float(b: bytes) -> float:
    """A VAX F-float (DEC processor files) → Python float."""
    return float(struct.unpack("<f", b[2:4] + b[0:2])[0]) / 4.0


class _Check:
    def __init__(self, data: bytes, src: str) -> None:
        self.d = data
        self.src = src

    def fail(self, where: str, msg: str) -> NoReturn:
        raise MeshFormatError(self.src, where, f"{where}: {msg}")

    def run(self) -> C3dLayout:
        d = self.d
        if len(d) < 512:
            self.fail("header", f"the file has {len(d)} bytes, fewer than the 512-byte C3D header")
        if d[1] != 0x50:
            self.fail("header", f"byte 2 is {d[1]:#04x}, not the C3D key 0x50: not a C3D file")
        pblock = d[0]
        if pblock < 2:
            self.fail("header word 1", f"the parameter section starts at block {pblock}; block 2 or later expected")
        pstart = (pblock - 1) * 512
        if pstart + 4 > len(d):
            self.fail("parameter section", f"starts at byte {pstart}, beyond the end of the file ({len(d)} bytes): truncated")
        proc = d[pstart + 3]
        if proc not in _PROCESSORS:
            self.fail("parameter section", f"processor type {proc} is not 84 (Intel), 85 (DEC) or 86 (MIPS)")
        self.proc = _PROCESSORS[proc]
        self.e = ">" if self.proc == "MIPS" else "<"
        nblocks = d[pstart + 2]
        if nblocks < 1:
            self.fail("parameter section", "says it has 0 blocks")
        pend = pstart + nblocks * 512
        if pend > len(d):
            self.fail("parameter section", f"has {nblocks} blocks (to byte {pend}), the file ends at byte {len(d)}: truncated")
        h = self._header()
        params = self._params(pstart + 4, pend)
        return self._layout(h, params)

    def i16(self, b: bytes) -> int:
        return int(struct.unpack(self.e + "h", b)[0])

    def u16(self, b: bytes) -> int:
        return int(struct.unpack(self.e + "H", b)[0])

    def f32(self, b: bytes) -> float:
        if self.proc == "DEC":
            return _dec_float(b)
        return float(struct.unpack(self.e + "f", b)[0])

    def _header(self) -> dict[str, Any]:
        d = self.d
        return {
            "points": self.u16(d[2:4]),
            "analog": self.u16(d[4:6]),
            "first": self.u16(d[6:8]),
            "last": self.u16(d[8:10]),
            "scale": self.f32(d[12:16]),
            "data_start": self.u16(d[16:18]),
            "rate": self.f32(d[20:24]),
        }

    def _params(self, q: int, end: int) -> dict[str, dict[str, Any]]:
        d = self.d
        groups: dict[int, str] = {}
        raw: list[tuple[int, str, int, tuple[int, ...], bytes, int]] = []
        n = 0
        while q < end:
            n += 1
            where = f"parameter record {n} (byte {q})"
            if q + 2 > end:
                break
            nlen = abs(struct.unpack("b", d[q : q + 1])[0])
            gid = struct.unpack("b", d[q + 1 : q + 2])[0]
            if nlen == 0:
                break
            if q + 2 + nlen + 2 > end:
                self.fail(where, "runs past the end of the parameter section")
            name_b = d[q + 2 : q + 2 + nlen]
            try:
                name = name_b.decode("ascii").strip().upper()
            except UnicodeDecodeError:
                self.fail(where, f"name {name_b[:16]!r} is not ASCII (a damaged record)")
            if not name or not all(c.isalnum() or c in "_-" for c in name):
                self.fail(where, f"name {name[:16]!r} is not a valid C3D name (a damaged record)")
            where = f"parameter record {n} '{name}' (byte {q})"
            op = q + 2 + nlen
            nxt = self.u16(d[op : op + 2])
            r = op + 2
            if gid < 0:
                if r + 1 > end:
                    self.fail(where, "runs past the end of the parameter section")
                groups[-gid] = name
            elif gid > 0:
                if r + 2 > end:
                    self.fail(where, "runs past the end of the parameter section")
                typ = struct.unpack("b", d[r : r + 1])[0]
                nd = d[r + 1]
                if typ not in _TYPES:
                    self.fail(where, f"data type {typ} is not -1 (char), 1 (byte), 2 (int16) or 4 (float)")
                if r + 2 + nd > end:
                    self.fail(where, "its dimensions run past the end of the parameter section")
                dims = tuple(d[r + 2 : r + 2 + nd])
                size = _TYPES[typ] * (math.prod(dims) if nd else 1)
                s = r + 2 + nd
                if s + size > end:
                    self.fail(where, f"its {size} data bytes run past the end of the parameter section (byte {end})")
                if nxt and s + size > op + nxt:
                    self.fail(where, f"its data ({size} bytes) overlap the next record (offset {nxt})")
                raw.append((gid, name, typ, dims, d[s : s + size], q))
            if nxt == 0:
                break
            q = op + nxt
        out: dict[str, dict[str, Any]] = {}
        for gid, name, typ, dims, data, _at in raw:
            if gid not in groups:
                self.fail(f"parameter {name}", f"belongs to group id {gid}, which the file does not define")
            out.setdefault(groups[gid], {})[name] = self._value(typ, dims, data)
        return out

    def _value(self, typ: int, dims: tuple[int, ...], data: bytes) -> Any:
        if typ == -1:
            if len(dims) <= 1:
                return [data.decode("latin-1").strip()]
            w = dims[0]
            if w == 0:
                return []
            return [data[i : i + w].decode("latin-1").strip() for i in range(0, len(data), w)]
        if typ == 1:
            return list(data)
        if typ == 2:
            return [self.i16(data[i : i + 2]) for i in range(0, len(data), 2)]
        return [self.f32(data[i : i + 4]) for i in range(0, len(data), 4)]

    def _layout(self, h: dict[str, Any], params: dict[str, dict[str, Any]]) -> C3dLayout:
        if "POINT" not in params:
            self.fail("POINT", "the parameter section has no POINT group")
        point = params["POINT"]

        def num(name: str, default: float | None) -> float:
            v = point.get(name)
            if v is None or len(v) == 0:
                if default is None:
                    self.fail(f"POINT:{name}", "missing")
                return float(default)
            if isinstance(v[0], str):
                self.fail(f"POINT:{name}", f"expected a number, got text {v[0]!r}")
            x = float(v[0])
            if not math.isfinite(x):
                self.fail(f"POINT:{name}", f"not finite ({x!r})")
            return x

        used = int(num("USED", h["points"]))
        if used < 0:
            used &= 0xFFFF  # stored as a signed int16 by some writers
        if used != h["points"]:
            self.fail("POINT:USED", f"{used} markers, but the header (word 2) says {h['points']}")
        scale = num("SCALE", h["scale"])
        if scale == 0:
            self.fail("POINT:SCALE", "is 0 (negative means float data, positive scales int16 data)")
        rate = num("RATE", h["rate"])
        if not rate > 0:
            self.fail("POINT:RATE", f"must be > 0 frames per second, got {rate:g}")
        dstart = int(num("DATA_START", h["data_start"]))
        if dstart < 0:
            dstart &= 0xFFFF
        if dstart < 2:
            self.fail("POINT:DATA_START", f"block {dstart}; the data start at block 2 or later")
        first, last = h["first"], h["last"]
        if first < 1 and last != 0:
            self.fail("header word 4", f"first frame {first}; C3D counts frames from 1")
        n_frames = last - first + 1 if last >= first else 0
        if point.get("FRAMES"):
            pf = num("FRAMES", None)
            if pf < 0:
                pf = int(pf) & 0xFFFF
            if n_frames and pf > n_frames and n_frames < 65535:
                self.fail("POINT:FRAMES", f"{int(pf)} frames, but the header (words 4-5) has frames {first}-{last}")
            if pf > n_frames and (n_frames or pf >= 65535):
                n_frames = int(pf)
        if last < first and n_frames < 65535:  # a header can only hold frame numbers < 65536
            self.fail("header words 4-5", f"last frame {last} is before first frame {first}: no frames")
        if n_frames <= 0:
            self.fail("header words 4-5", f"last frame {last} is before first frame {first}: no frames")
        labels: list[str] = []
        for key in ["LABELS"] + [f"LABELS{i}" for i in range(2, 100)]:
            v = point.get(key)
            if v is None:
                break
            if v and not isinstance(v[0], str):
                self.fail(f"POINT:{key}", "expected text labels")
            labels.extend(v)
        if used and len(labels) < used:
            self.fail("POINT:LABELS", f"{len(labels)} labels for {used} markers (POINT:USED)")
        units = point.get("UNITS")
        if units is not None and units and not isinstance(units[0], str):
            self.fail("POINT:UNITS", "expected text (e.g. 'mm')")
        word = 4 if scale < 0 else 2
        need = (dstart - 1) * 512 + n_frames * (used * 4 + h["analog"]) * word
        if need > len(self.d):
            self.fail(
                "data section",
                f"{n_frames} frames of {used} markers and {h['analog']} analog samples need the file "
                f"to reach byte {need}; it ends at byte {len(self.d)}: truncated",
            )
        return C3dLayout(self.proc, used, h["analog"], first, n_frames, scale, rate, dstart, params)


def check_c3d(path: str | Path) -> C3dLayout:
    """Check a C3D file's structure (see the module docstring) without ezc3d.

    Raises
    ------
    MeshFormatError
        Names the file and the header word or ``GROUP:PARAMETER``.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise MeshFormatError(p, "file", f"cannot read: {exc}") from None
    return _Check(data, str(p)).run()


def read_markers(path: str | Path) -> MarkerSequence:
    """Read the 3-D markers of a C3D file (see the module docstring).

    Raises
    ------
    FileNotFoundError
        No such file.
    MeshFormatError
        Malformed file, unknown ``POINT:UNITS``, a non-finite position of a
        marker that is not marked missing.
    """
    p = Path(path)
    src = str(p)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    lay = check_c3d(p)
    point = lay.params["POINT"]
    units_v = point.get("UNITS") or []
    unit = (units_v[0] if units_v else "").strip()
    if not unit:
        unit = "mm"
        log.warning("%s: POINT:UNITS is missing; millimetres assumed (the usual C3D unit)", p.name)
    mpu = UNITS_TO_METRES.get(unit.lower())
    if mpu is None:
        raise MeshFormatError(src, "POINT:UNITS", f"POINT:UNITS: unknown unit {unit!r} (expected one of mm, cm, dm, m, in)")
    import ezc3d

    try:
        c = ezc3d.c3d(str(p), extract_forceplat_data=False)
    except Exception as exc:  # ezc3d raises RuntimeError / IOError with C++ messages
        raise MeshFormatError(src, "file", f"ezc3d cannot read the file: {exc}") from None
    pts = np.asarray(c["data"]["points"], np.float64)
    if pts.ndim != 3 or pts.shape[0] < 3 or pts.shape[1] != lay.n_points:
        raise MeshFormatError(src, "data section", f"data section: ezc3d read points of shape {pts.shape}, expected (4, {lay.n_points}, frames)")
    P = np.ascontiguousarray(np.moveaxis(pts[:3], (0, 1, 2), (2, 1, 0)))  # (F, m, 3)
    res = c["data"].get("meta_points", {}).get("residuals")
    gap = ~np.isfinite(P).all(axis=2)
    if res is not None:
        R = np.asarray(res, np.float64).reshape(-1, lay.n_points, P.shape[0])[0].T
        gap |= R < 0
    # a coordinate that is not finite where the marker is not missing is damage, not a gap
    bad = ~np.isfinite(P).all(axis=2) & ~gap
    if bad.any():
        f, j = (int(x) for x in np.argwhere(bad)[0])
        raise MeshFormatError(src, "data section", f"data section: frame {f + lay.first_frame} marker {j} is not finite")
    P[gap] = np.nan
    labels = list(point.get("LABELS") or [])
    for i in range(2, 100):
        if f"LABELS{i}" not in point:
            break
        labels.extend(point[f"LABELS{i}"])
    names = [(labels[j].strip() if j < len(labels) else "") or f"marker_{j}" for j in range(lay.n_points)]
    if len(set(names)) != len(names):
        log.warning("%s: marker labels repeat (%s)", p.name, sorted({n for n in names if names.count(n) > 1})[:5])
    rate = float(c["parameters"]["POINT"]["RATE"]["value"][0]) if "RATE" in c["parameters"]["POINT"] else lay.rate
    return MarkerSequence(
        names=tuple(names),
        positions=P * mpu,
        fps=rate,
        units=unit,
        first_frame=int(c["header"]["points"]["first_frame"]) + 1,
        source=src,
    )
