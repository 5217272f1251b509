"""The fast parser's ``f`` lines: the grammar of every face corner checked with vectorised byte tests."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from workbench.io.obj.scan import (
    _DIGIT,
    _F,
    _F_KIND,
    _FK_BAD,
    _FK_BLANK,
    _FK_F,
    _FK_MINUS,
    _FK_SLASH,
    _LF,
    _MINUS,
    _SLASH,
    _Scan,
)


def _parse_faces(scan: _Scan, block: bytes) -> tuple[NDArray[np.int64], NDArray[np.int64]] | None:
    """(first index of every corner, corners per face) of the 'f' lines, or None.

    Every corner must match ``v``, ``v/vt``, ``v/vt/vn`` or ``v//vn`` (optional
    minus signs), the grammar of the line parser's regular expression, tested
    at each '/' and '-': a '-' follows a blank or '/' and precedes a digit; a
    '/' follows a digit or '/' and precedes a digit, '-' or '/'; a corner holds
    at most two '/'. Then a corner starts with a digit or '-', and 'v//vn' is
    the only place two '/' meet.
    """
    n = scan.f_idx.size
    b = np.frombuffer(block, dtype=np.uint8)
    kind = _F_KIND[b]
    line_start = np.concatenate(([0], np.flatnonzero(b == _LF) + 1))
    if (
        np.count_nonzero(kind == _FK_BAD)
        or np.count_nonzero(kind == _FK_F) != n
        or not (b[line_start] == _F).all()
    ):
        return None
    space = kind >= _FK_BLANK  # blanks and each line's 'f'
    start = ~space
    start[1:] &= space[:-1]
    end = ~space
    end[:-1] &= space[1:]
    tok, tok_end = np.flatnonzero(start), np.flatnonzero(end) + 1
    size = b.size
    slash = np.flatnonzero(kind == _FK_SLASH)
    minus = np.flatnonzero(kind == _FK_MINUS)
    if slash.size:
        if slash[-1] == size - 1:
            return None
        before, after = b[slash - 1], b[slash + 1]
        if not (
            (_DIGIT[before] | (before == _SLASH)).all()
            and (_DIGIT[after] | (after == _MINUS) | (after == _SLASH)).all()
        ):
            return None
        corner = np.searchsorted(tok, slash, side="right") - 1
        if (corner[2:] == corner[:-2]).any():  # three '/' in one corner
            return None
    if minus.size:
        if minus[-1] == size - 1:
            return None
        before = kind[minus - 1]
        if not (((before >= _FK_BLANK) | (before == _FK_SLASH)).all() and _DIGIT[b[minus + 1]].all()):
            return None
    sizes = np.bincount(np.searchsorted(line_start, tok, side="right") - 1, minlength=n)
    if (sizes < 3).any():
        return None
    # the vertex index: from the corner's start (after a '-') to its first '/' or its end
    negative = b[tok] == _MINUS
    digits_at = tok + negative
    field_end = tok_end.copy()
    if slash.size:
        k = np.searchsorted(slash, tok)
        has = k < slash.size
        first_slash = slash[np.minimum(k, slash.size - 1)]
        cut = has & (first_slash < tok_end)
        field_end[cut] = first_slash[cut]
    length = field_end - digits_at
    if int(length.max()) > 18:
        return None  # beyond int64: let the line parser report the huge index
    ids = np.zeros(tok.size, dtype=np.int64)
    for c in range(int(length.max())):
        more = length > c
        digit = b[np.minimum(digits_at + c, size - 1)].astype(np.int64) - 48
        ids = np.where(more, ids * 10 + digit, ids)
    return np.where(negative, -ids, ids), sizes
