"""Strict Wavefront OBJ reader that keeps polygons and groups.

Why hand-written: trimesh (and most loaders) triangulate on load and drop the
polygon list, merge or drop vertices, and skip lines they cannot parse. Face
editing needs the artist's quads (exports write them back), vertex ids that
match the file exactly (MakeHuman targets and OBJ shape folders index them),
the ``g``/``o`` groups (eyes, teeth, tongue become named parts) and an error
with a line number on a damaged file rather than a silently different mesh.

Accepted statements: ``v x y z [w]`` (or ``v x y z r g b`` vertex colours; only
x y z are kept), ``f`` with ``v``, ``v/vt``, ``v/vt/vn``, ``v//vn`` corners and
negative (relative) indices, ``g``, ``o``. Ignored: ``vt vn vp usemtl mtllib s l
p`` and comments. Free-form geometry and unknown statements are errors.

Two parsers, one result. The fast one works on the raw bytes with numpy: it
finds the line starts once, classifies every line by its first bytes, cuts out
the ``v`` and ``f`` lines as blocks and converts each block in one call
(``np.fromstring``), checking the grammar of every face corner with vectorised
byte tests. It only accepts what it can prove the line-by-line parser would
read the same way; on anything else (a malformed line, an exponent it cannot
place, exotic line breaks, an unknown statement) it steps aside and the
line-by-line parser reads the file and reports the error with its line number.
:func:`read_obj_with_template` / :func:`read_positions_if_same_faces` let the
folder reader parse the face lines of a shape set once: the other files are
only checked to hold byte-identical face lines, and only their ``v`` lines that
differ from the neutral's are converted.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from workbench.core.polygons import Polygons
from workbench.geometry.mesh_checks import MeshFormatError, check_faces, check_vertices
from workbench.io.base import ImportedFace

__all__ = [
    "DESCRIPTION",
    "ObjTemplate",
    "detect",
    "parse_obj_bytes",
    "parse_obj_text",
    "read",
    "read_obj",
    "read_obj_with_template",
    "read_positions_if_same_faces",
]

DESCRIPTION = "a .obj file (neutral mesh only; polygons and g/o groups kept)"

_IGNORED = frozenset(
    {"vt", "vn", "vp", "usemtl", "mtllib", "s", "l", "p", "mg", "usemap", "maplib"}
)
_FREEFORM = frozenset(
    {
        "cstype",
        "deg",
        "bmat",
        "step",
        "curv",
        "curv2",
        "surf",
        "parm",
        "trim",
        "hole",
        "scrv",
        "sp",
        "end",
        "con",
    }
)
# one face corner: v, v/vt, v/vt/vn, v//vn (indices may be negative)
_CORNER_RE = r"(-?\d+)(?:/-?\d+(?:/-?\d+)?|//-?\d+)?"
_CORNER = re.compile(_CORNER_RE, re.ASCII)
# all corners of all faces joined by single spaces, checked in one call
_CORNERS = re.compile(
    f"{_CORNER_RE.replace('(-', '(?:-')}(?: {_CORNER_RE.replace('(-', '(?:-')})*", re.ASCII
)


def detect(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() == ".obj"


def read(path: Path) -> ImportedFace:
    return read_obj(path)


def _decode(data: bytes) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        # group names from old tools may be Latin-1; every byte decodes, and any
        # binary garbage in v/f lines is then reported as a parse error
        return data.decode("latin-1")


def _read_bytes(p: Path) -> bytes:
    try:
        return p.read_bytes()
    except IsADirectoryError:
        raise MeshFormatError(p, "path", "is a folder, expected an .obj file") from None


def read_obj(path: str | Path) -> ImportedFace:
    """Read one OBJ file.

    Parameters
    ----------
    path : str or Path
        The .obj file.

    Returns
    -------
    ImportedFace
        ``vertices`` (n, 3) float64, ``polygons`` as in the file, ``face_groups``
        from ``g``/``o`` lines (None if the file has none), no shapes, unknown
        units and up axis.

    Raises
    ------
    MeshFormatError
        Empty file, garbled line, NaN/inf coordinate, face index out of range,
        face with fewer than 3 corners or a repeated corner, duplicate or
        zero-area face. The message gives the file name and line number.
    """
    p = Path(path)
    return parse_obj_bytes(_read_bytes(p), p)


def parse_obj_bytes(data: bytes, source: str | Path = "<bytes>") -> ImportedFace:
    """Parse the bytes of an OBJ file (see :func:`read_obj`); ``source`` is used in messages."""
    return _parse(data, str(source))[0]


def parse_obj_text(text: str, source: str | Path = "<string>") -> ImportedFace:
    """Parse OBJ text (see :func:`read_obj`); ``source`` is used in messages."""
    try:
        data = text.encode("utf-8")
    except UnicodeEncodeError:  # lone surrogates: only the line parser reads these
        return _parse_lines(text, str(source))
    return _parse(data, str(source))[0]


@dataclass(frozen=True)
class _LineIndex:
    bytes: NDArray[np.uint8]
    starts: NDArray[np.int64]
    lengths: NDArray[np.int64]
    line_of_byte: NDArray[np.int32]
    offset_in_line: NDArray[np.int32]


class ObjTemplate:
    """What a file of the same topology is compared with: the face lines and ``v`` lines of a neutral.

    Built by :func:`read_obj_with_template`; used by :func:`read_positions_if_same_faces`.
    Holds the neutral's face lines (bytes), the number of ``v`` lines before each block
    of ``f`` lines (relative indices depend on it), and its ``v`` lines with their
    positions, so that a shape file's ``v`` lines that are byte-identical to the
    neutral's need not be converted again.
    """

    def __init__(
        self,
        face_bytes: bytes,
        v_before: tuple[int, ...],
        v_block: bytes,
        vertices: NDArray[np.float64],
    ) -> None:
        self.face_bytes = face_bytes
        self.v_before = v_before
        self.vertices = vertices
        self.n_vertices = int(vertices.shape[0])
        self._v_block = v_block
        self._index: _LineIndex | None = None

    def _line_index(self) -> _LineIndex:
        if self._index is None:
            a = np.frombuffer(self._v_block, dtype=np.uint8)
            nl = np.flatnonzero(a == _LF)
            starts = np.concatenate(([0], nl + 1))
            lengths = np.concatenate((nl, [a.size])) - starts
            line_of_byte = np.repeat(np.arange(starts.size, dtype=np.int32), lengths + 1)[: a.size]
            # minus each line's start: add a line's start in another block to find the byte there
            offset = np.arange(a.size, dtype=np.int32) - starts[line_of_byte].astype(np.int32)
            self._index = _LineIndex(a, starts, lengths, line_of_byte, offset)
        return self._index

    def changed_lines(
        self, block: NDArray[np.uint8], nl: NDArray[np.int64]
    ) -> NDArray[np.bool_] | None:
        """Which ``v`` lines of ``block`` (newlines at ``nl``) differ from the neutral's, or None.

        None when the line counts differ. A line is unchanged when it has the same
        bytes as the neutral's line with the same index.
        """
        ref = self._line_index()
        if nl.size != ref.starts.size - 1:
            return None
        if block.size == ref.bytes.size and np.array_equal(nl + 1, ref.starts[1:]):
            # every line kept its length (the usual case with fixed decimals): compare in place
            return np.logical_or.reduceat(ref.bytes != block, ref.starts)
        starts = np.concatenate(([0], nl + 1))
        lengths = np.concatenate((nl, [block.size])) - starts
        # byte k of the neutral's line i is compared with byte k of line i here
        idx = starts.astype(np.int32)[ref.line_of_byte]
        idx += ref.offset_in_line
        np.minimum(idx, block.size - 1, out=idx)
        differs = np.logical_or.reduceat(ref.bytes != block[idx], ref.starts)
        return differs | (lengths != ref.lengths)


def read_obj_with_template(path: str | Path) -> tuple[ImportedFace, ObjTemplate | None]:
    """:func:`read_obj`, plus an :class:`ObjTemplate` of the file (None if the fast parser stepped aside)."""
    p = Path(path)
    return _parse(_read_bytes(p), str(p))


def read_positions_if_same_faces(
    path: str | Path, template: ObjTemplate
) -> NDArray[np.float64] | None:
    """Vertex positions of an OBJ file whose face lines match ``template`` byte for byte.

    Parameters
    ----------
    path : str or Path
        The .obj file.
    template : ObjTemplate
        From :func:`read_obj_with_template` on the file whose faces are expected.

    Returns
    -------
    (n, 3) float64 or None
        The positions when the file is well formed, has ``template.n_vertices``
        finite vertices and the same face lines after the same number of
        vertices, so :func:`read_obj` would return these positions and the
        same polygons (up to the zero-area test, which depends on positions:
        callers check it). None otherwise: call :func:`read_obj` for the full
        parse and its error.
    """
    data = _read_bytes(Path(path))
    scan = _scan(data)
    if scan is None or scan.f_idx.size == 0 or scan.v_idx.size != template.n_vertices:
        return None
    runs = _runs(scan.f_idx)
    if _v_before(scan, runs) != template.v_before:
        return None
    if _block(scan, runs) != template.face_bytes:
        return None
    parsed = _parse_vertices(scan, template)
    if parsed is None or not np.isfinite(parsed[0]).all():
        return None
    return parsed[0]


# ---- the fast, vectorised parser ------------------------------------------------------


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


@dataclass
class _Tokens:
    """What both parsers hand to :func:`_assemble`."""

    V: NDArray[np.float64]
    v_lines: NDArray[np.int64]
    ids: NDArray[np.int64]  # vertex index of every corner, as written (1-based or negative)
    sizes: NDArray[np.int64]
    f_lines: NDArray[np.int64]
    f_nv: NDArray[np.int64]  # vertices defined before each face
    f_group: NDArray[np.int32]
    group_names: list[str]
    any_group: bool


def _parse(data: bytes, src: str) -> tuple[ImportedFace, ObjTemplate | None]:
    scan = _scan(data)
    if scan is not None and scan.v_idx.size and scan.f_idx.size:
        verts = _parse_vertices(scan)
        runs = _runs(scan.f_idx)
        face_block = _block(scan, runs)
        faces = _parse_faces(scan, face_block) if verts is not None else None
        if verts is not None and faces is not None:
            # group ids in order of first appearance; a face takes the last g/o line before it
            gid: dict[str, int] = {}
            event_line = np.array([i for i, _ in scan.groups], dtype=np.int64)
            event_gid = np.array(
                [-1] + [gid.setdefault(name, len(gid)) for _, name in scan.groups], dtype=np.int32
            )
            f_group = event_gid[np.searchsorted(event_line, scan.f_idx)]
            tokens = _Tokens(
                V=verts[0],
                v_lines=verts[1],
                ids=faces[0],
                sizes=faces[1],
                f_lines=scan.f_idx + 1,
                f_nv=np.searchsorted(scan.v_idx, scan.f_idx),
                f_group=f_group,
                group_names=list(gid),
                any_group=bool(scan.groups),
            )
            face = _assemble(tokens, src)
            template = ObjTemplate(face_block, _v_before(scan, runs), verts[2], face.vertices)
            return face, template
    return _parse_lines(_decode(data), src), None


# ---- the line-by-line parser: the reference, and the one that words the errors ---------


def _parse_lines(text: str, src: str) -> ImportedFace:
    if not text.strip():
        raise MeshFormatError(src, "file", "empty file")

    v_tokens: list[list[str]] = []
    v_lines: list[int] = []
    f_tokens: list[str] = []  # every face corner token, all faces concatenated
    f_sizes: list[int] = []
    f_lines: list[int] = []
    f_nv: list[int] = []  # vertices defined before each face (for negative indices)
    f_group: list[int] = []
    group_names: list[str] = []
    group_ids: dict[str, int] = {}
    current_group = -1
    any_group = False

    def fail(lineno: int, field: str, msg: str) -> MeshFormatError:
        return MeshFormatError(src, field, f"line {lineno}: {msg}")

    for lineno, raw in enumerate(text.splitlines(), start=1):
        parts = raw.split()
        if not parts:
            continue
        key = parts[0]
        if key == "v":
            n = len(parts) - 1
            if n not in (3, 4, 6, 7):
                raise fail(
                    lineno,
                    "v",
                    f"vertex needs 3 coordinates (x y z [w] or x y z r g b), got {n}: "
                    f"{raw.strip()[:80]!r}",
                )
            v_tokens.append(parts[1:4])
            v_lines.append(lineno)
        elif key == "f":
            if len(parts) < 4:
                raise fail(
                    lineno,
                    "f",
                    f"face needs at least 3 corners, got {len(parts) - 1}: {raw.strip()[:80]!r}",
                )
            f_tokens.extend(parts[1:])
            f_sizes.append(len(parts) - 1)
            f_lines.append(lineno)
            f_nv.append(len(v_tokens))
            f_group.append(current_group)
        elif key[0] == "#" or key in _IGNORED:
            continue
        elif key in ("g", "o"):
            any_group = True
            name = " ".join(parts[1:]) or "default"
            if name not in group_ids:
                group_ids[name] = len(group_names)
                group_names.append(name)
            current_group = group_ids[name]
        elif key in _FREEFORM:
            raise fail(lineno, key, f"free-form geometry ('{key}') is not supported")
        else:
            raise fail(lineno, "line", f"unknown statement {key[:40]!r}")

    if not v_tokens:
        raise MeshFormatError(src, "v", "no vertices ('v' lines)")
    if not f_sizes:
        raise MeshFormatError(src, "f", "no faces ('f' lines)")

    try:
        V = np.array(v_tokens, dtype=np.float64)
    except ValueError:
        # find the first bad line for the message
        for toks, lineno in zip(v_tokens, v_lines, strict=True):
            try:
                [float(t) for t in toks]
            except ValueError:
                raise fail(
                    lineno, "v", f"vertex coordinate is not a number: {' '.join(toks)[:80]!r}"
                ) from None
        raise MeshFormatError(src, "v", "vertex coordinates are not numbers") from None
    n = V.shape[0]
    sizes = np.asarray(f_sizes, dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)

    ids: np.ndarray | None = None
    if _CORNERS.fullmatch(" ".join(f_tokens)) is not None:
        try:
            ids = np.array([t.split("/", 1)[0] for t in f_tokens], dtype=np.int64)
        except (ValueError, OverflowError):
            ids = None  # e.g. a 30-digit index: the slow path below reports it
    if ids is None:
        check_vertices(V, src, "v", line_numbers=v_lines)
        for c, tok in enumerate(f_tokens):
            line = f_lines[int(np.searchsorted(offsets, c, side="right") - 1)]
            m = _CORNER.fullmatch(tok)
            if m is None:
                raise fail(
                    line, "f", f"bad face corner {tok[:40]!r} (expected v, v/vt, v/vt/vn or v//vn)"
                )
            if abs(int(m.group(1))) > n:
                raise fail(
                    line, "f", f"face index {m.group(1)[:40]} out of range (file has {n} vertices)"
                )
        raise MeshFormatError(src, "f", "unreadable face indices")  # pragma: no cover

    tokens = _Tokens(
        V=V,
        v_lines=np.asarray(v_lines, dtype=np.int64),
        ids=ids,
        sizes=sizes,
        f_lines=np.asarray(f_lines, dtype=np.int64),
        f_nv=np.asarray(f_nv, dtype=np.int64),
        f_group=np.asarray(f_group, dtype=np.int32),
        group_names=group_names,
        any_group=any_group,
    )
    return _assemble(tokens, src)


def _assemble(t: _Tokens, src: str) -> ImportedFace:
    """Check the parsed numbers and build the face (shared by both parsers)."""
    V = check_vertices(t.V, src, "v", line_numbers=t.v_lines)
    n = V.shape[0]
    sizes, ids = t.sizes, t.ids
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)

    def fail(c: int, msg: str) -> MeshFormatError:
        line = int(t.f_lines[int(np.searchsorted(offsets, c, side="right") - 1)])
        return MeshFormatError(src, "f", f"line {line}: {msg}")

    zero = ids == 0
    if zero.any():
        raise fail(int(np.argmax(zero)), "face index 0 (OBJ indices start at 1)")
    # negative indices count back from the last vertex defined before the face line
    nv = np.repeat(t.f_nv, sizes)
    corners = np.where(ids > 0, ids - 1, nv + ids)
    bad = (corners < 0) | (corners >= n)
    if bad.any():
        c = int(np.argmax(bad))
        raise fail(
            c,
            f"face index {int(ids[c])} out of range (file has {n} vertices"
            + (f", {int(nv[c])} before this line)" if ids[c] < 0 else ")"),
        )
    polygons = Polygons(corners.astype(np.int32), offsets)
    check_faces(polygons, n, src, vertices=V, line_numbers=t.f_lines)

    return ImportedFace(
        vertices=V,
        polygons=polygons,
        face_groups=t.f_group if t.any_group else None,
        group_names=t.group_names if t.any_group else [],
        shapes=[],
        source_files=[src],
        units=None,
        up_axis=None,
    )
