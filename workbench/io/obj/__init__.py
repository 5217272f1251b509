"""Strict Wavefront OBJ reader that keeps polygons and groups.

Why hand-written: trimesh (and most loaders) triangulate on load and drop the
polygon list, merge or drop vertices, and skip lines they cannot parse. Face
editing needs the artist's quads (exports write them back), vertex ids that
match the file exactly (MakeHuman targets and OBJ shape folders index them),
the ``g``/``o`` groups (eyes, teeth, tongue become named parts) and an error
with a line number on a damaged file rather than a silently different mesh.
The accepted statements are listed in :mod:`~workbench.io.obj.lines`.

Two parsers, one result (:mod:`~workbench.io.obj.assemble`). The fast one
works on the raw bytes with numpy: it finds the line starts once, classifies
every line by its first bytes, cuts out the ``v`` and ``f`` lines as blocks
(:mod:`~workbench.io.obj.scan`) and converts each block in one call
(``np.fromstring``, :mod:`~workbench.io.obj.vertices`), checking the grammar
of every face corner with vectorised byte tests
(:mod:`~workbench.io.obj.faces`). It only accepts what it can prove the
line-by-line parser would read the same way; on anything else (a malformed
line, an exponent it cannot place, exotic line breaks, an unknown statement)
it steps aside and the line-by-line parser (:mod:`~workbench.io.obj.lines`)
reads the file and reports the error with its line number.
:func:`read_obj_with_template` / :func:`read_positions_if_same_faces` let the
folder reader parse the face lines of a shape set once: the other files are
only checked to hold byte-identical face lines, and only their ``v`` lines that
differ from the neutral's are converted (:mod:`~workbench.io.obj.template`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.base import ImportedFace
from workbench.io.obj.assemble import _assemble, _Tokens
from workbench.io.obj.faces import _parse_faces
from workbench.io.obj.lines import _parse_lines
from workbench.io.obj.scan import _block, _runs, _scan, _v_before
from workbench.io.obj.template import ObjTemplate
from workbench.io.obj.vertices import _parse_vertices

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
