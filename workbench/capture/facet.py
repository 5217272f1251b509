"""``model.capture``: track a take on this model, and put a result on its timeline as one undo step."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from workbench.capture.result import TrackResult
from workbench.core.shapes import ModelError

if TYPE_CHECKING:
    from workbench.animation.tracks import Timeline
    from workbench.capture.replay import ReplayResult
    from workbench.core.state import FaceState

__all__ = ["CaptureFacet"]


class CaptureFacet:
    """Performance capture on one model (Bouaziz et al. 2013); keeps nothing of its own.

    ``track`` reads the model and returns a :class:`TrackResult` (the model is not
    changed); ``apply`` writes a result to the timeline (one undo step).
    """

    def __init__(self, model: FaceState) -> None:
        self._model = model

    def __repr__(self) -> str:
        return ("<capture: track(frames, vertex_ids=...) -> TrackResult; apply(result); "
                "replay(frames, vertex_ids=...) -> ReplayResult; apply_replay(result)>")

    def track(self, frames: Any, **kwargs: Any) -> TrackResult:
        """:func:`workbench.capture.track` on this model (same arguments after ``frames``)."""
        from workbench.capture.track import track

        return track(self._model, frames, **kwargs)

    def timeline(self, result: TrackResult, *, tolerance: float = 0.01, start: float = 0.0,
                 head_pose: bool = True) -> Timeline:
        """The model's timeline with ``result`` keyed in (not applied): what :meth:`apply` installs.

        The result's tracks (``weights/<shape>`` of every non-derived shape, and ``head_pose``)
        replace the timeline's tracks of the same names; other tracks stay. The range grows
        to cover the take; the frame rate becomes the take's when the timeline had no keys.
        """
        return self._merged(result, tolerance, start, head_pose)[0]

    def _merged(self, result: TrackResult, tolerance: float, start: float, head_pose: bool
                ) -> tuple[Timeline, Timeline]:
        m = self._model
        if not isinstance(result, TrackResult):
            raise ModelError(f"capture: result must be a TrackResult, got {type(result).__name__}")
        if tuple(result.shape_names) != tuple(m.shape_names):
            raise ModelError(
                f"capture: result was tracked for {len(result.shape_names)} shapes "
                f"{list(result.shape_names[:3])}..., the model has {len(m.shape_names)} "
                f"{list(m.shape_names[:3])}... (shape list edited since tracking: track again)"
            )
        new = result.to_timeline(tolerance, start=start, head_pose=head_pose)
        old = m.slot("tracks")
        tracks = dict(old.tracks)
        tracks.update(new.tracks)
        fps = old.fps if old.tracks else result.fps
        lo, hi = new.start, new.end
        if old.tracks:
            lo, hi = min(lo, old.start), max(hi, old.end)
        return old.replace(fps=fps, start=lo, end=hi, tracks=tracks), new

    def apply(self, result: TrackResult, *, tolerance: float = 0.01, start: float = 0.0,
              head_pose: bool = True, label: str | None = None) -> Timeline:
        """Key ``result`` on the timeline (see :meth:`timeline`) as one undo step; returns the new timeline.

        Everything is built and checked before the model is touched: an error leaves it as it was.
        """
        m = self._model
        with m.lock:
            tl, new = self._merged(result, tolerance, start, head_pose)
            n_keys = sum(len(t.keys) for t in new.tracks.values())
            m.timeline.set(tl, label or f"Apply capture ({result.n_frames} frames, {n_keys} keys)")  # type: ignore[attr-defined]
            return tl

    # ------------------------------------------------------------ marker replay
    def replay(self, frames: Any, **kwargs: Any) -> ReplayResult:
        """:func:`workbench.capture.replay` on this model (same arguments after ``frames``); the model is unchanged."""
        from workbench.capture.replay import replay

        return replay(self._model, frames, **kwargs)  # type: ignore[arg-type]

    def apply_replay(self, result: ReplayResult, *, tolerance: float = 0.01, start: float = 0.0,
                     head_pose: bool = True, label: str | None = None) -> Timeline:
        """Install a replay as one undo step: the markers become the handles, their wrinkles the
        model's, and the take is keyed (weights, ``handles`` offsets, head pose).

        The timeline's other tracks stay, except a ``handles`` track (it keyed the old handles).
        With ``tolerance=0`` every frame is keyed and the model plays ``result.meshes`` exactly.
        Everything is built and checked first: an error leaves the model as it was.
        """
        from workbench.capture.replay import ReplayResult

        m = self._model
        if not isinstance(result, ReplayResult):
            raise ModelError(f"capture: result must be a ReplayResult, got {type(result).__name__}")
        if result.meshes.shape[1] != m.n_vertices or tuple(result.shape_names) != tuple(m.shape_names):
            raise ModelError(
                f"capture: the replay was made for {result.meshes.shape[1]} vertices and "
                f"{len(result.shape_names)} shapes, the model has {m.n_vertices} and {len(m.shape_names)} "
                "(replay again on this model)")
        with m.lock:
            new = result.to_timeline(tolerance, start=start, head_pose=head_pose)
            old = m.slot("tracks")
            tracks = {k: v for k, v in old.tracks.items() if k != "handles"}
            tracks.update(new.tracks)
            fps = old.fps if old.tracks else result.fps
            lo, hi = new.start, new.end
            if old.tracks:
                lo, hi = min(lo, old.start), max(hi, old.end)
            tl = old.replace(fps=fps, start=lo, end=hi, tracks=tracks)
            n_keys = sum(len(t.keys) for t in new.tracks.values())
            with m.undo_group(label or f"Apply marker replay ({result.n_frames} frames, {n_keys} keys)"):
                m.handles.set(result.handles, label="Markers as handles")  # type: ignore[attr-defined]
                if result.wrinkles is not None:
                    m.set_slot("wrinkles", result.wrinkles, "Wrinkles on the marker graph")
                m.timeline.set(tl, "Key the replay")  # type: ignore[attr-defined]
            return tl
