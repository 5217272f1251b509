// Keyframe timeline front end (anywidget ESM; plain DOM + 2D canvas, no three.js).
//
// The Python side (widgets/timeline/) owns every edit: the front end only draws the
// state it is sent (`_tracks`, `_curve`, `time`, `playing`, ...) and turns mouse and
// keyboard input into small JSON messages ({type: "scrub" | "move_key" | ...}).
// Previews during a drag (a key diamond following the mouse, a tangent handle
// rotating) are drawn locally; the edit is sent once, on release, so one drag is
// one undo step in the model. Dragging the playhead is a "scrub" gesture of the
// project's gesture protocol (timeline/transport.js).
//
// Modules (Python side: widgets/timeline/):
//   timeline/view.js       TimelineView: state, wiring, test hooks (one per display)
//   timeline/toolbar.js    toolbar, head-pose sliders;  timeline/chips.js  expression chips
//   timeline/tracks.js     main canvas drawing;         timeline/keys.js   key editing
//   timeline/curve.js      curve view and tangents;     timeline/transport.js  scrub, playback
//   timeline/style.js      sizes, colours, stylesheet
//   shared/playback.js     which timelines play (the viewports draw in draft resolution)
//
// Test hooks (attributes on the root element, client/page CSS pixels, refreshed on
// every draw and on scroll; el.fwbHooks() recomputes them on demand):
//   data-time, data-playhead-x, data-ruler-y, data-axis = {x0, x1, t0, t1},
//   data-keys = [[track, index, time, x, y], ...], data-tangents =
//   [[track, index, side, x, y], ...] (curve view), data-playing, data-selected,
//   data-draws, data-scrub-sent, data-error, data-head-pose = [yaw, pitch, roll]
//   as the sliders show them; on the chip strip, data-thumbs = number of chips
//   showing a picture.
import { TimelineView } from "./timeline/view.js";

export default {
  render({ model, el }) {
    const view = new TimelineView(model, el);
    return () => view.dispose();
  },
};
