"""``TimelineWidget``: keyframe timeline of a :class:`workbench.FaceModel` (Pighin et al. 1998 §5).

The widget draws ``model.timeline.value`` (a :class:`workbench.animation.tracks.Timeline`):
a time ruler with frame ticks at the timeline's fps, a playhead, one row per
track with its keys as diamonds (squares for step keys), and a curve view of
the selected weight track with the Bézier tangent handles of its keys.
Region-weight tracks (a keyed marker fit) and the head pose are vector tracks:
rows without a curve view. Three sliders give the head's yaw, pitch and roll
(degrees about the model's up, side and front axes,
:func:`workbench.animation.tracks.head_rotation_from_euler`); they show the pose
keyed at the playhead and "Key head pose" keys what they say there. It only
*observes* the model (``events.tracks``, ``events.time``, ``events.expressions``,
``events.shapes``) and edits it only through the ``model.timeline`` facet and
``model.set_time``, so undo, other views and Python cells stay in agreement:

=============================  ==========================================================
front end                      model call
=============================  ==========================================================
drag the playhead / ruler      ``set_time(t)``: a "scrub" gesture (one message in flight)
drag a key diamond, release    ``timeline.move_key(track, i, t)`` — one undo step per drag
Delete / Backspace / button    ``timeline.delete_keys([(track, i), ...])`` — one undo step
double-click a row             ``timeline.key_track(track, t)`` (the weight, what the
                               track's family records now, or its value at the playhead)
"Key" / "Key handles"          ``timeline.key_weights(time)`` / ``handles.key(time)``
yaw/pitch/roll, "Key head pose" ``timeline.key_head_pose(time, rotation)`` (translation kept)
interpolation selector         ``timeline.set_interpolations([(track, i), ...], kind)``
drag a tangent handle          ``timeline.set_tangents(track, i, in_tangent=, out_tangent=)``
double-click a tangent handle  ``timeline.set_tangents(track, i, mode="auto_clamped")``
drop an expression chip        ``expressions.key(t, name)`` (HTML5 drag and drop)
"Key selected expression"      ``expressions.key(time, gallery.selected)``
fps field                      ``timeline.set_fps(fps)``
Play / Pause / Loop            kernel-side asyncio task calling ``set_time``
=============================  ==========================================================

Layout:

* :mod:`widgets.timeline.widget` - the ``TimelineWidget`` anywidget: traits, the
  model -> front end refresh, message dispatch;
* :mod:`widgets.timeline.messages` - the front end's edit messages -> ``model.timeline``
  calls (and the Python API doing the same: ``key_head_pose``, ``key_selected_expression``);
* :mod:`widgets.timeline.playback` - kernel-side playback with frame flow control;
* :mod:`widgets.timeline.state` - the JSON the front end draws (tracks, curve samples);
* :mod:`widgets.timeline.bundle` - the front end's ESM bundle.

Why hand-written: ipywidgets has no timeline/dope-sheet widget, and the
available anywidget/ipywidget timeline components (e.g. vis-timeline wrappers)
edit their own event lists rather than calling a model, have no Bézier
tangent view and would need a CDN or a large bundle. The front end is plain
DOM + a 2D canvas (``widgets/js/src/timeline.js`` and ``widgets/js/src/timeline/``),
bundled by esbuild to ``widgets/static/timeline.js``.
"""

from widgets.timeline.bundle import TIMELINE_BUNDLE, load_timeline_bundle
from widgets.timeline.playback import FRAME_ACK_TIMEOUT_S, FRAMES_IN_FLIGHT, STATUS_PERIOD_S
from widgets.timeline.state import CURVE_SAMPLES, curve_samples, timeline_state, view_range
from widgets.timeline.widget import TimelineWidget

__all__ = [
    "CURVE_SAMPLES",
    "FRAMES_IN_FLIGHT",
    "FRAME_ACK_TIMEOUT_S",
    "STATUS_PERIOD_S",
    "TIMELINE_BUNDLE",
    "TimelineWidget",
    "curve_samples",
    "load_timeline_bundle",
    "timeline_state",
    "view_range",
]
