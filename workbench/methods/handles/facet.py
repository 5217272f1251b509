"""``model.handles``: the undoable edits of the handle set and the shell stiffness.

Reads like the :class:`HandleSet` it holds (``model.handles.vertices``,
``.offsets``, ``.names``, ``.mirror``, ``len(model.handles)``); ``.value`` is
the set itself. Every edit replaces the ``handles`` (or ``shell_stiffness``)
slot, so it is one undo step, or part of the open interaction's step.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.core.shapes import BlendShape, ModelError
from workbench.methods.handles.handle_set import HandleSet

#: the timeline track of the handle offsets: (h, 3) model units, the handle layer's "pose keys"
HANDLES_TRACK = "handles"

if TYPE_CHECKING:
    from workbench.core.state import FaceState
    from workbench.methods.handles.layer import HandleLayer
    from workbench.methods.handles.shell import ShellDeformer


def check_handles(model: FaceState, value: Any) -> HandleSet:
    """Slot check: a HandleSet whose vertex ids are in range."""
    if not isinstance(value, HandleSet):
        raise ModelError(f"handles: expected a HandleSet, got {type(value).__name__}")
    n = model.n_vertices
    if len(value) and (value.vertices.min() < 0 or value.vertices.max() >= n):
        raise ModelError(f"handles: vertex ids must be in 0..{n - 1}")
    return value


def check_stiffness(model: FaceState, value: Any) -> tuple[float, float]:
    """Slot check: ``(k_s, k_b)`` finite, non-negative, not both zero."""
    try:
        ks, kb = (float(x) for x in value)
    except (TypeError, ValueError):
        raise ModelError(f"shell_stiffness: expected (k_s, k_b), got {value!r}") from None
    if not (math.isfinite(ks) and math.isfinite(kb)) or ks < 0 or kb < 0 or (ks == 0 and kb == 0):
        raise ModelError(f"need finite k_s >= 0, k_b >= 0, not both zero; got {ks}, {kb}")
    return ks, kb


class HandlesFacet:
    """The handle-editing tool of one model (see the module docstring)."""

    def __init__(self, model: FaceState) -> None:
        self._model = model

    # ------------------------------------------------------------------ reading
    @property
    def value(self) -> HandleSet:
        return self._model.slot("handles")

    @property
    def vertices(self) -> NDArray[np.int32]:
        return self.value.vertices

    @property
    def offsets(self) -> NDArray[np.float32]:
        return self.value.offsets

    @property
    def names(self) -> tuple[str, ...]:
        return self.value.names

    @property
    def mirror(self) -> NDArray[np.int32]:
        return self.value.mirror

    def __len__(self) -> int:
        return len(self.value)

    def __repr__(self) -> str:
        return f"<handles: {len(self)} on {self._model.n_vertices} vertices, stiffness {self.stiffness}>"

    @property
    def stiffness(self) -> tuple[float, float]:
        """``(k_s, k_b)`` of the thin-shell energy."""
        return self._model.slot("shell_stiffness")

    @property
    def layer(self) -> HandleLayer:
        return self._model.pipeline.layer("handles")  # type: ignore[return-value]

    def deformer(self) -> ShellDeformer:
        """The shell deformer of the current handle set (built on first use)."""
        return self.layer.deformer(self._model.view())

    def basis(self) -> tuple[NDArray[np.float32], NDArray[np.int64]]:
        """The linear shell of the current handle set: ``(B, columns)``.

        ``B`` (n, H_unique) float32, read-only, and ``columns`` (H,) int, the column of
        each handle: the handle layer adds ``B @ u`` with ``u[j]`` the mean offset of
        the handles in column ``j`` (a view can evaluate the shell itself, e.g. on the
        GPU). Builds the deformer on first use.
        """
        _, B, columns = self.layer.control_basis(self._model.view())
        return B, columns

    def displacement(self) -> NDArray[np.float32]:
        """(n, 3) float32 copy of what the handle layer adds to the live mesh."""
        return self._model.layer_displacement("handles")

    # -------------------------------------------------------------------- edits
    def set(self, handles: HandleSet, label: str = "Edit handles") -> None:
        """Replace the handle set (undoable)."""
        self._model.set_slot("handles", handles, label)

    def add(self, vertex: int, name: str | None = None, mirror: int = -1) -> int:
        """Add a handle at ``vertex`` (undoable); returns its index.

        ``mirror`` is an existing handle that mirrors this one (or -1); linked both ways.
        """
        m = self._model
        with m.lock:
            h = self.value
            v = int(vertex)
            if not 0 <= v < m.n_vertices:
                raise ModelError(f"add_handle: vertex must be in 0..{m.n_vertices - 1}, got {vertex}")
            idx = len(h)
            mir = np.append(h.mirror, np.int32(mirror))
            if mirror >= 0:
                if mirror >= idx:
                    raise ModelError(f"add_handle: mirror must index an existing handle, got {mirror}")
                mir[mirror] = idx
            self.set(
                HandleSet(np.append(h.vertices, v), np.vstack([h.offsets, np.zeros((1, 3), np.float32)]),
                          (*h.names, name or f"h{idx}"), mir),
                label=f"Add handle {name or idx}",
            )
            return idx

    def remove(self, index: int) -> None:
        """Remove handle ``index`` (undoable); mirror links to it are cleared."""
        with self._model.lock:
            h = self.value
            if not 0 <= index < len(h):
                raise ModelError(f"remove_handle: index must be in 0..{len(h) - 1}, got {index}")
            keep = np.arange(len(h)) != index
            remap = np.cumsum(keep) - 1
            mir = h.mirror[keep]
            mir = np.where(mir == index, -1, np.where(mir >= 0, remap[np.maximum(mir, 0)], -1))
            self.set(
                HandleSet(h.vertices[keep], h.offsets[keep],
                          tuple(n for i, n in enumerate(h.names) if i != index), mir),
                label=f"Remove handle {h.names[index]}",
            )

    def set_offsets(self, offsets: ArrayLike, label: str = "Move handles") -> None:
        """Set every handle's offset, (h, 3), on top of the mesh below (undoable)."""
        with self._model.lock:
            h = self.value
            o = np.asarray(offsets, dtype=np.float32).reshape(-1, 3)
            if o.shape[0] != len(h):
                raise ModelError(f"set_handle_offsets: expected ({len(h)}, 3) offsets, got {o.shape}")
            if not np.isfinite(o).all():
                raise ModelError("set_handle_offsets: offsets must be finite")
            self.set(dataclasses.replace(h, offsets=o), label)

    def key(self, time: float, interpolation: str = "bezier") -> None:
        """Key the current handle offsets at ``time`` on the timeline (its ``"handles"`` track); one undo step."""
        if not len(self.value):
            raise ModelError("handles.key: the model has no handles")
        self._model.timeline.key_track(HANDLES_TRACK, time, interpolation)  # type: ignore[attr-defined]

    def move(self, index: int, offset: ArrayLike, *, symmetric: bool = False) -> None:
        """Set one handle's offset (3,); with ``symmetric`` its mirror gets the x-reflected offset.

        The reflection assumes the face is symmetric about x = 0 of model space.
        Inside an interaction (a drag) it joins the drag's undo step.
        """
        with self._model.lock:
            h = self.value
            if not 0 <= index < len(h):
                raise ModelError(f"move_handle: index must be in 0..{len(h) - 1}, got {index}")
            o = h.offsets.copy()
            o[index] = np.asarray(offset, dtype=np.float32).reshape(3)
            m = int(h.mirror[index])
            if symmetric and m >= 0:
                o[m] = o[index] * np.array([-1.0, 1.0, 1.0], np.float32)
            self.set_offsets(o, label=f"Move handle {h.names[index]}")

    def reset_offsets(self) -> None:
        """Zero every handle offset (undoable)."""
        self.set_offsets(np.zeros((len(self), 3)), label="Reset handles")

    def prepare(self) -> None:
        """Build the shell basis for the current handle set now (else on the first drag).

        Reports through :meth:`set_progress`; ~0.3 s at 20k vertices, ~2 s at 80k with CHOLMOD.
        """
        with self._model.lock:
            if len(self):
                self.deformer()

    def set_stiffness(self, k_s: float, k_b: float) -> None:
        """Change ``(k_s, k_b)`` as one undo step (the basis is rebuilt on the next evaluation)."""
        new = check_stiffness(self._model, (k_s, k_b))
        if new != self.stiffness:  # setting the current values records nothing
            self._model.set_slot("shell_stiffness", new, "Shell stiffness")

    def set_progress(self, progress: Callable[[float, str], None] | None) -> None:
        """Callback ``progress(fraction, message)`` for long basis precomputes (a progress bar)."""
        self.layer.progress = progress

    def bake_to_shape(self, name: str) -> BlendShape:
        """Turn the handle layer into a new blendshape ``name`` at weight 1 and zero the offsets.

        One undo step; the face looks the same before and after.
        """
        m = self._model
        with m.lock:
            if m.interacting:
                raise ModelError("bake_handles_to_shape: finish the drag first")
            delta = self.displacement()
            with m.undo_group(f"Bake handles to {name}"):
                m.add_shape(name, delta, weight=1.0)
                self.reset_offsets()
            return m.shape(name)
