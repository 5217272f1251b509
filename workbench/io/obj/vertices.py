"""The fast parser's ``v`` lines: converted as one block (fixed decimals, else ``np.fromstring``).

Each block is converted in one call; only what the line-by-line parser would
read the same way is accepted, anything else returns None so that parser reads
the file.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from workbench.io.obj.scan import (
    _K_BAD,
    _K_DOT,
    _K_EXP,
    _K_SIGN,
    _K_V,
    _LF,
    _V,
    _V_BLANK,
    _V_KIND,
    _V_KINDS,
    _block,
    _runs,
    _Scan,
)
from workbench.io.obj.template import ObjTemplate


def _parse_vertices(
    scan: _Scan, template: ObjTemplate | None = None
) -> tuple[NDArray[np.float64], NDArray[np.int64], bytes] | None:
    """(positions (n, 3), 1-based line numbers, the 'v' lines as one block) or None.

    With a ``template``, lines byte-identical to the template's take its positions
    and only the others are converted.
    """
    n = scan.v_idx.size
    if n == 0:
        return None
    block = _block(scan, _runs(scan.v_idx))
    b = np.frombuffer(block, dtype=np.uint8)
    nl = np.flatnonzero(b == _LF)
    changed = None if template is None else template.changed_lines(b, nl)
    if changed is None or changed.all():
        V = _convert_v_lines(b, nl, n)
    elif not changed.any():
        V = template.vertices.copy() if template is not None else None
    else:
        assert template is not None
        lengths = np.diff(np.concatenate(([-1], nl, [b.size - 1])))  # with the newline
        sub = b[np.repeat(changed, lengths)]
        if sub[-1] == _LF:
            sub = sub[:-1]
        part = _convert_v_lines(sub, np.flatnonzero(sub == _LF), int(changed.sum()))
        V = None
        if part is not None:
            V = template.vertices.copy()
            V[changed] = part
    if V is None:
        return None
    return V, scan.v_idx + 1, block


def _convert_v_lines(
    b: NDArray[np.uint8], nl: NDArray[np.int64], n: int
) -> NDArray[np.float64] | None:
    """x y z of ``n`` 'v' lines (bytes ``b``, newlines at ``nl``), or None if any is unusual."""
    kind = _V_KIND[b]
    kinds = [int(np.count_nonzero(kind == k)) for k in range(_V_KINDS)]
    line_start = np.concatenate(([0], nl + 1))
    # nothing but numbers and each line's leading 'v' (nan, inf, garbage: the line parser)
    if kinds[_K_BAD] or kinds[_K_V] != n or not (b[line_start] == _V).all():
        return None
    space = _V_BLANK[b]
    start = ~space
    start[1:] &= space[:-1]
    end = ~space
    end[:-1] &= space[1:]
    ts, te = np.flatnonzero(start), np.flatnonzero(end) + 1
    line_end = np.concatenate((nl, [b.size]))
    if ts.size == 3 * n and (ts[::3] >= line_start).all() and (ts[2::3] < line_end).all():
        counts = np.full(n, 3)  # each line holds its own three numbers (tokens are sorted)
    else:
        counts = np.bincount(np.searchsorted(nl, ts), minlength=n)
    values = None
    if kinds[_K_EXP] == 0:
        values = _fixed_decimals(b, ts, te, kinds)
    if values is None:
        try:
            values = np.fromstring(b.tobytes().replace(b"v", b" "), dtype=np.float64, sep=" ")
        except ValueError:
            return None
        if values.size != ts.size:
            return None
    if (counts == 3).all():
        return values.reshape(-1, 3)
    if not np.isin(counts, (3, 4, 6, 7)).all():
        return None
    first = np.concatenate(([0], np.cumsum(counts)[:-1]))
    return values[first[:, None] + np.arange(3)]


_POW10 = 10.0 ** np.arange(23)


def _fixed_decimals(
    b: NDArray[np.uint8], ts: NDArray[np.int64], te: NDArray[np.int64], kinds: list[int]
) -> NDArray[np.float64] | None:
    """The numbers at ``b[ts[i]:te[i]]`` when all are written ``[-+]ddd.ddd`` with the same
    number of decimals and at most 15 digits (as ``"%.6f"`` writes them); else None.

    The digits are read as an integer (exact in float64 below 2**53) and divided
    by a power of ten (exact): one correctly rounded division, so the result is
    the nearest double to the decimal, as :func:`float` and ``np.fromstring`` give.
    Numpy releases the GIL in these loops (``np.fromstring`` does not), so files
    read by several threads are converted in parallel.
    """
    n_tok = ts.size
    if n_tok == 0 or kinds[_K_DOT] != n_tok:
        return None
    length = te - ts
    dots0 = np.flatnonzero(b[ts[0] : te[0]] == ord("."))
    if dots0.size != 1:
        return None
    decimals = int(length[0] - 1 - dots0[0])
    dot_at = te - 1 - decimals
    if not ((dot_at >= ts).all() and (b[dot_at] == ord(".")).all()):
        return None  # one '.' per number (as many as numbers), all at the same place from the end
    first = b[ts]
    signed = (first == ord("-")) | (first == ord("+"))
    if int(np.count_nonzero(signed)) != kinds[_K_SIGN]:
        return None  # a sign inside a number
    digits = length - 1 - signed
    if digits.min() < 1 or digits.max() > 15:
        return None
    # digit columns, numbers right-aligned: column c holds byte te - width + c of each number
    width = int(length.max())
    skip = width - length + signed  # columns before the first digit
    value = np.zeros(n_tok)
    te32 = te.astype(np.int32)
    for c in range(width):
        if c == width - 1 - decimals:
            continue  # the '.'
        digit = b[np.maximum(te32 - (width - c), 0)].astype(np.float64)
        digit -= 48.0
        digit[skip > c] = 0.0
        value *= 10.0  # Horner: every partial value is an integer below 2**53, exact
        value += digit
    value /= _POW10[decimals]
    return np.where(first == ord("-"), -value, value)
