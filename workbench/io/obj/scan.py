"""The fast parser's first stage: split the raw bytes into lines and classify them.

The fast parser works on the raw bytes with numpy: it finds the line starts
once, classifies every line by its first bytes and cuts out the ``v`` and
``f`` lines as blocks (converted by :mod:`~workbench.io.obj.vertices` and
:mod:`~workbench.io.obj.faces`). Also the byte tables those stages test with.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from workbench.io.obj.lines import _IGNORED


def _lut(chars: bytes) -> NDArray[np.bool_]:
    table = np.zeros(256, dtype=bool)
    table[list(chars)] = True
    return table


_V_BLANK = _lut(b" \t\r\nv")
# byte kinds in 'v' lines, counted in one pass
_K_BAD, _K_OK, _K_DOT, _K_SIGN, _K_EXP, _K_V = range(6)
_V_KINDS = 6
_V_KIND = np.zeros(256, dtype=np.uint8)
_V_KIND[list(b"0123456789 \t\r\n")] = _K_OK
_V_KIND[ord(".")] = _K_DOT
_V_KIND[list(b"+-")] = _K_SIGN
_V_KIND[list(b"eE")] = _K_EXP
_V_KIND[ord("v")] = _K_V
_DIGIT = _lut(b"0123456789")
# byte kinds in 'f' lines; the blank kinds (and each line's 'f') are >= _FK_BLANK
_FK_BAD, _FK_DIGIT, _FK_SLASH, _FK_MINUS, _FK_BLANK, _FK_F = range(6)
_F_KIND = np.full(256, _FK_BAD, dtype=np.uint8)
_F_KIND[list(b"0123456789")] = _FK_DIGIT
_F_KIND[ord("/")] = _FK_SLASH
_F_KIND[ord("-")] = _FK_MINUS
_F_KIND[list(b" \t\r\n")] = _FK_BLANK
_F_KIND[ord("f")] = _FK_F
# bytes that str.splitlines() or str.split() treat as line breaks / white space but the
# byte scanner does not: files holding them are read by the line parser
_ODD_BYTES = (b"\x0b", b"\x0c", b"\x1c", b"\x1d", b"\x1e", b"\x1f")
_ODD_NON_ASCII = (b"\x85", b"\xe2\x80\xa8", b"\xe2\x80\xa9")
_V, _F, _T, _N, _P, _HASH, _LF, _CR, _SP, _TAB = (ord(c) for c in "vftnp#\n\r \t")
_SLASH, _MINUS = ord("/"), ord("-")


@dataclass
class _Scan:
    data: bytes
    starts: NDArray[np.int64]  # byte offset where each line starts
    ends: NDArray[np.int64]  # ... and ends (before its '\n')
    v_idx: NDArray[np.int64]  # 0-based index of every 'v' line
    f_idx: NDArray[np.int64]  # ... of every 'f' line
    groups: list[tuple[int, str]]  # (line index, name) of every 'g'/'o' line


def _scan(data: bytes) -> _Scan | None:
    """Split ``data`` into lines and classify them; None when the line parser must read it."""
    if any(b in data for b in _ODD_BYTES):
        return None
    if b"\r" in data and data.count(b"\r") != data.count(b"\r\n"):  # a lone CR breaks a line
        return None
    codec = "ascii"
    if not data.isascii():
        if any(b in data for b in _ODD_NON_ASCII):
            return None
        try:
            data.decode("utf-8")
            codec = "utf-8"
        except UnicodeDecodeError:
            codec = "latin-1"
    arr = np.frombuffer(data, dtype=np.uint8)
    n = arr.size
    nl = np.flatnonzero(arr == _LF)
    starts = np.concatenate(([0], nl + 1))
    ends = np.concatenate((nl, [n]))
    if starts[-1] == n:  # the file ends with a newline
        starts, ends = starts[:-1], ends[:-1]

    def byte_at(k: int) -> NDArray[np.uint8]:  # a newline past the end of the file
        i = starts + k
        out = arr[np.minimum(i, n - 1)]
        out[i >= n] = _LF
        return out

    c0, c1, c2 = byte_at(0), byte_at(1), byte_at(2)
    blank1 = (c1 == _SP) | (c1 == _TAB)
    is_v = (c0 == _V) & blank1
    is_f = (c0 == _F) & blank1
    vt_vn_vp = (
        (c0 == _V)
        & ((c1 == _T) | (c1 == _N) | (c1 == _P))
        & ((c2 == _SP) | (c2 == _TAB) | (c2 == _LF) | (c2 == _CR))
    )
    skip = vt_vn_vp | (c0 == _HASH) | (c0 == _LF) | ((c0 == _CR) & (c1 == _LF))
    groups: list[tuple[int, str]] = []
    for i in np.flatnonzero(~(is_v | is_f | skip)).tolist():
        parts = data[starts[i] : ends[i]].decode(codec).split()
        if not parts:
            continue
        key = parts[0]
        if key[0] == "#" or key in _IGNORED:
            continue
        if key in ("g", "o"):
            groups.append((i, " ".join(parts[1:]) or "default"))
            continue
        return None  # an indented v/f line, free-form geometry, an unknown statement
    return _Scan(data, starts, ends, np.flatnonzero(is_v), np.flatnonzero(is_f), groups)


def _runs(idx: NDArray[np.int64]) -> list[tuple[int, int]]:
    """(first, last) line index of each run of consecutive lines in ``idx``."""
    if idx.size == 0:
        return []
    br = np.flatnonzero(np.diff(idx) != 1)
    first = idx[np.concatenate(([0], br + 1))]
    last = idx[np.concatenate((br, [idx.size - 1]))]
    return list(zip(first.tolist(), last.tolist(), strict=True))


def _block(scan: _Scan, runs: list[tuple[int, int]]) -> bytes:
    """The lines of ``runs`` joined by newlines: the k-th line is the k-th line of the runs."""
    s, e, d = scan.starts, scan.ends, scan.data
    return b"\n".join(d[s[a] : e[b]] for a, b in runs)


def _v_before(scan: _Scan, runs: list[tuple[int, int]]) -> tuple[int, ...]:
    firsts = np.array([a for a, _ in runs], dtype=np.int64)
    return tuple(np.searchsorted(scan.v_idx, firsts).tolist())
