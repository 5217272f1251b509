// Transport: the playhead scrub, playback flow control and the playback registry.
//
// Dragging the playhead (or the ruler) is a "scrub" gesture of the project's one gesture
// protocol (GestureClient, ../viewport/gestures.js): {type: "scrub", phase: "start" |
// "move" | "end", gesture, seq, time}, ONE message in flight, the next (the newest
// position) sent when Python's {type: "scrub_ack", seq} arrives. Python sets the model's
// time for each; the time is not an undo step, so no model interaction is held. The Start
// button and the arrow keys send one {type: "scrub", time, seq: -1} without a phase.
//
// During playback the kernel sends {type: "frame", seq} after each frame; the answer
// {type: "frame_ack", seq} goes from the next animation frame, i.e. after the viewport
// drew the geometry that arrived before it (widgets/timeline/playback.py).
// Methods of TimelineView (./view.js).

import { announcePlayback as announce } from "../shared/playback.js";
import { GestureClient } from "../viewport/gestures.js";

function clamp(x, a, b) {
  return Math.min(Math.max(x, a), b);
}

export const transportMethods = {
  initTransport() {
    let seq = 0;
    this.scrub = { time: null, local: null, sent: 0 }; // local: the playhead drawn while dragging
    this.scrubClient = new GestureClient(this.model, { nextSeq: () => (seq += 1) }, "scrub", {
      body: () => {
        this.scrub.sent += 1;
        this.root.setAttribute("data-scrub-sent", String(this.scrub.sent));
        return { time: this.scrub.time };
      },
    });
  },

  // press on the ruler or the playhead: the gesture starts at t (seconds)
  scrubBegin(t) {
    this.scrubPreview(t);
    this.scrubClient.begin(performance.now());
  },

  scrubTo(t) {
    this.scrubPreview(t);
    this.scrubClient.update(performance.now());
  },

  // release (or pointercancel): the last position is kept
  scrubEnd() {
    this.scrubClient.end();
    this.scrub.local = null;
  },

  scrubPreview(t) {
    const st = this.state();
    this.scrub.time = clamp(t, st.view[0], st.view[1]);
    this.scrub.local = this.scrub.time;
    this.requestDraw(false);
  },

  // one jump, no gesture (Start button, arrow keys)
  jumpTo(t) {
    this.send({ type: "scrub", time: t, seq: -1 });
  },

  playheadTime() {
    const local = this.drag && this.drag.kind === "scrub" ? this.scrub.local : null;
    return local !== null && local !== undefined ? local : this.model.get("time");
  },

  onMessage(msg) {
    if (!msg || typeof msg !== "object") return;
    if (msg.type === "frame") {
      // playback flow control: answer once the browser reached its next animation
      // frame, i.e. after the viewport drew the geometry sent before this message
      requestAnimationFrame(() => this.send({ type: "frame_ack", seq: msg.seq }));
    } else if (msg.type === "scrub_ack") {
      this.scrubClient.onAck(msg);
    }
  },

  // Viewports of the same face model draw in draft resolution while a timeline plays
  // (software WebGL only, see softwareWebGL() in viewport/util.js): tell them through the
  // shared playback registry (shared/playback.js), keyed by the model's `_scene`.
  announcePlayback(playing) {
    if (playing === !!this.announcedPlaying) return;
    this.announcedPlaying = playing;
    if (!this.playbackId) this.playbackId = `tl-${Math.random().toString(36).slice(2)}`;
    announce(this.playbackId, this.model.get("_scene") || "", playing);
  },
};
