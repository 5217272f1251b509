// TimelineView: one display of a TimelineWidget. The class holds the state of the view and
// its wiring; what it does lives in one module per concept, mixed into its prototype:
//   toolbar.js    the DOM: toolbar, head-pose sliders, canvases; their listeners and state
//   chips.js      the expression chips (thumbnails) and their HTML5 drop onto the tracks
//   tracks.js     the main canvas: layout, ruler, rows, key diamonds, playhead
//   keys.js       key editing in the main canvas: select, drag, double-click, keyboard
//   curve.js      the curve view: the selected weight track and its tangent handles
//   transport.js  scrub gesture, playback frame acks, the shared playback registry
// and the test hooks below.

import { chipMethods } from "./chips.js";
import { curveMethods } from "./curve.js";
import { keyMethods } from "./keys.js";
import { RULER } from "./style.js";
import { toolbarMethods } from "./toolbar.js";
import { trackMethods } from "./tracks.js";
import { transportMethods } from "./transport.js";

// traits whose change redraws everything (`time` only moves the playhead)
const SYNCED = ["_tracks", "_curve", "playing", "loop", "status", "_error", "expressions",
  "_saved_expressions", "_thumbnails", "_gallery_selected", "selected_keys", "selected_track", "_has_handles",
  "_head_pose"]; // prettier-ignore

export class TimelineView {
  constructor(model, root) {
    this.model = model;
    this.root = root;
    this.selected = []; // [[track, index], ...] (mirrors the `selected_keys` trait)
    this.drag = null; // current pointer gesture in the main canvas
    this.curveDrag = null; // current tangent drag in the curve view
    this.dropTime = null; // HTML5 drag-over position (seconds) or null
    this.draws = 0;
    this.raf = 0;
    this.geom = null; // last layout, for hit tests and hooks
    this.disposers = [];
    this.thumbs = new Map(); // name -> {bytes, url}: object URLs of the chip pictures
    this.thumbsRaw = undefined; // the `_thumbnails` value they were made from
    this.initTransport();
    this.build();
    this.bind();
    this.sync();
  }

  on(target, type, fn, opts) {
    target.addEventListener(type, fn, opts);
    this.disposers.push(() => target.removeEventListener(type, fn, opts));
  }

  bind() {
    const m = this.model;
    const redraw = () => this.sync();
    // the playhead moves every frame during playback: redraw only the playhead layer
    const onTime = () => this.requestDraw(false);
    m.on("change:time", onTime);
    this.disposers.push(() => m.off("change:time", onTime));
    for (const name of SYNCED) {
      m.on(`change:${name}`, redraw);
      this.disposers.push(() => m.off(`change:${name}`, redraw));
    }
    const onMsg = (msg) => this.onMessage(msg);
    m.on("msg:custom", onMsg);
    this.disposers.push(() => m.off("msg:custom", onMsg));

    this.bindToolbar();
    this.bindKeys();
    this.bindDrop();
    this.bindCurve();

    this.resizeObs = new ResizeObserver(() => this.requestDraw());
    this.resizeObs.observe(this.root);
    this.disposers.push(() => this.resizeObs.disconnect());
    // hooks hold client coordinates: refresh them when anything scrolls
    this.on(document, "scroll", () => this.writeHooks(), { capture: true, passive: true });
    this.root.fwbHooks = () => this.writeHooks();
  }

  dispose() {
    this.announcePlayback(false);
    for (const d of this.disposers) d();
    this.disposers = [];
    for (const { url } of this.thumbs.values()) URL.revokeObjectURL(url);
    this.thumbs.clear();
    if (this.raf) cancelAnimationFrame(this.raf);
  }

  send(content) {
    this.model.send(content);
  }

  // --------------------------------------------------------------- state
  state() {
    return this.model.get("_tracks") || { fps: 30, start: 0, end: 0, view: [0, 2], tracks: [] };
  }

  track(name) {
    return this.state().tracks.find((t) => t.name === name) || null;
  }

  sync() {
    const sel = this.model.get("selected_keys") || [];
    // keep the local selection when Python echoes it back; drop indices that vanished
    this.selected = sel.filter(([tn, i]) => {
      const tr = this.track(tn);
      return tr && i >= 0 && i < tr.times.length;
    });
    this.syncToolbar();
    this.announcePlayback(!!this.model.get("playing"));
    this.syncHeadPose();
    this.syncChips();
    this.requestDraw();
  }

  // ------------------------------------------------------------- test hooks
  writeHooks() {
    const g = this.geom;
    if (!g) return null;
    const r = this.canvas.getBoundingClientRect();
    const cr = this.curveCanvas.getBoundingClientRect();
    const st = this.state();
    const keys = [];
    st.tracks.forEach((tr, row) => {
      tr.times.forEach((t, i) => keys.push([tr.name, i, t, r.left + g.tx(t), r.top + g.rowY(row)]));
    });
    const t = this.model.get("time");
    const hooks = {
      "data-time": String(t),
      "data-playhead-x": String(r.left + g.tx(t)),
      "data-ruler-y": String(r.top + RULER / 2),
      "data-axis": JSON.stringify({ x0: r.left + g.x0, x1: r.left + g.x1, t0: g.v0, t1: g.v1 }),
      "data-keys": JSON.stringify(keys),
      "data-tangents": JSON.stringify(
        (this.tangentHooks || []).map(([tn, i, side, x, y]) => [tn, i, side, cr.left + x, cr.top + y]),
      ),
      "data-selected": JSON.stringify(this.selected),
      "data-draws": String(this.draws),
    };
    for (const [k, v] of Object.entries(hooks)) {
      if (this.root.getAttribute(k) !== v) this.root.setAttribute(k, v);
    }
    return hooks;
  }
}

Object.assign(TimelineView.prototype, toolbarMethods, chipMethods, trackMethods, keyMethods, curveMethods,
  transportMethods); // prettier-ignore
