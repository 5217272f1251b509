"""A neutral's face and ``v`` lines, to read shape files of the same topology quickly.

:func:`~workbench.io.obj.read_obj_with_template` /
:func:`~workbench.io.obj.read_positions_if_same_faces` let the folder reader
parse the face lines of a shape set once: the other files are only checked to
hold byte-identical face lines, and only their ``v`` lines that differ from the
neutral's are converted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from workbench.io.obj.scan import _LF


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
