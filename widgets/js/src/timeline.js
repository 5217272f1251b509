// Keyframe timeline front end (anywidget ESM; plain DOM + 2D canvas, no dependencies).
//
// The Python side (widgets/timeline.py) owns every edit: this file only draws the
// state it is sent (`_tracks`, `_curve`, `time`, `playing`, ...) and turns mouse and
// keyboard input into small JSON messages ({type: "scrub" | "move_key" | ...}).
// Previews during a drag (a key diamond following the mouse, a tangent handle
// rotating) are drawn locally; the edit is sent once, on release, so one drag is
// one undo step in the model.
//
// Test hooks (attributes on the root element, client/page CSS pixels, refreshed on
// every draw and on scroll; el.fwbHooks() recomputes them on demand):
//   data-time, data-playhead-x, data-ruler-y, data-axis = {x0, x1, t0, t1},
//   data-keys = [[track, index, time, x, y], ...], data-tangents =
//   [[track, index, side, x, y], ...] (curve view), data-playing, data-selected,
//   data-draws, data-scrub-sent, data-error, data-head-pose = [yaw, pitch, roll]
//   as the sliders show them; on the chip strip, data-thumbs = number of chips
//   showing a picture.
//
// Expression chips: one per name in `expressions`, draggable (HTML5 drag with the
// name as application/x-fwb-expression) onto the tracks or the ruler. When
// `_thumbnails` (name -> PNG bytes, arriving as binary buffers) has pictures, the
// strip is a one-row, horizontally scrolling gallery of small thumbnails with the
// name under each; without any, the chips are text.

import { announcePlayback as announce } from "./shared/playback.js";

const GUTTER = 150; // px: track labels
const RULER = 30; // px: time ruler height
const ROW = 22; // px: one track row
const RIGHT_PAD = 12;
const CURVE_H = 150;
const KEY_R = 6; // diamond half size
const HANDLE_R = 5;
const DRAG_START_PX = 3;
const ACK_TIMEOUT_MS = 2000;
const THUMB = 48; // px: chip picture (CSS size; the PNGs are larger, sharp on HiDPI)

const COLORS = {
  bg: "#fbfbfc",
  ruler: "#eceef2",
  rowAlt: "#f3f4f7",
  rowSel: "#e3ecfb",
  grid: "#d5d9e0",
  gridMajor: "#b4bac4",
  text: "#333a44",
  textDim: "#6b7380",
  key: "#e0a526",
  keyStep: "#8c8c8c",
  keyLinear: "#3f9b5a",
  keySel: "#1f6fe5",
  keyStroke: "#5a4310",
  playhead: "#d63a3a",
  curve: "#1f6fe5",
  handleAuto: "#7c8898",
  handleUser: "#c2410c",
  drop: "#1f6fe5",
};

const CSS = `
.fwb-timeline { font: 12px/1.3 system-ui, -apple-system, "Segoe UI", sans-serif; color: ${COLORS.text};
  border: 1px solid #d0d4da; border-radius: 4px; background: #fff; outline: none; user-select: none;
  display: flex; flex-direction: column; gap: 4px; padding: 4px; box-sizing: border-box; width: 100%; }
.fwb-timeline:focus { border-color: #7aa7f0; }
.fwb-tl-toolbar { display: flex; flex-wrap: wrap; align-items: center; gap: 4px; }
.fwb-tl-toolbar button { font: inherit; padding: 2px 8px; border: 1px solid #c3c8d0; border-radius: 3px;
  background: #f6f7f9; cursor: pointer; }
.fwb-tl-toolbar button:hover { background: #eceff3; }
.fwb-tl-toolbar button:disabled { opacity: .45; cursor: default; }
.fwb-tl-toolbar button.fwb-on { background: #dbe7fb; border-color: #7aa7f0; }
.fwb-tl-toolbar label { display: inline-flex; align-items: center; gap: 3px; }
.fwb-tl-toolbar input[type=number] { width: 52px; font: inherit; }
.fwb-tl-toolbar select { font: inherit; }
.fwb-tl-sep { width: 1px; height: 18px; background: #d0d4da; margin: 0 3px; }
.fwb-tl-status { margin-left: auto; color: ${COLORS.textDim}; white-space: nowrap; overflow: hidden;
  text-overflow: ellipsis; max-width: 46%; }
.fwb-tl-status.fwb-err { color: #b42318; }
.fwb-tl-chips { display: flex; flex-wrap: wrap; gap: 3px; max-height: 42px; overflow-y: auto; }
.fwb-tl-chip { padding: 1px 6px; border-radius: 9px; background: #eef1f5; border: 1px solid #d3d8df;
  cursor: grab; font-size: 11px; }
.fwb-tl-chip.fwb-saved { background: #fdf1d8; border-color: #e8c880; font-weight: 600; }
.fwb-tl-chips-label { color: ${COLORS.textDim}; font-size: 11px; padding: 1px 2px; }
.fwb-tl-chips.fwb-tl-thumbs { flex-wrap: nowrap; max-height: none; overflow-x: auto; overflow-y: hidden;
  align-items: stretch; padding-bottom: 2px; }
.fwb-tl-thumbs .fwb-tl-chips-label { align-self: center; flex: 0 0 52px; white-space: normal; }
.fwb-tl-chip.fwb-tl-thumb { flex: 0 0 auto; display: flex; flex-direction: column; align-items: center;
  gap: 1px; width: ${THUMB + 8}px; padding: 2px 1px 1px; border-radius: 4px; box-sizing: border-box; }
.fwb-tl-chip.fwb-tl-thumb:hover { border-color: #7aa7f0; }
.fwb-tl-thumb img, .fwb-tl-thumb .fwb-tl-noimg { display: block; width: ${THUMB}px; height: ${THUMB}px;
  border-radius: 3px; background: #fff; pointer-events: none; }
.fwb-tl-thumb .fwb-tl-noimg { display: flex; align-items: center; justify-content: center;
  color: ${COLORS.textDim}; font-size: 18px; background: #e4e7ec; }
.fwb-tl-chip-name { max-width: ${THUMB + 6}px; overflow: hidden; text-overflow: ellipsis; white-space: nowrap;
  font-size: 10px; line-height: 12px; }
.fwb-tl-canvas, .fwb-tl-curve-canvas { display: block; width: 100%; touch-action: none; }
.fwb-tl-curve-box { border-top: 1px solid #e2e5ea; }
.fwb-tl-head { display: flex; flex-wrap: wrap; align-items: center; gap: 8px; }
.fwb-tl-head label { display: inline-flex; align-items: center; gap: 3px; }
.fwb-tl-head input[type=range] { width: 96px; }
.fwb-tl-head button { font: inherit; padding: 2px 8px; border: 1px solid #c3c8d0; border-radius: 3px;
  background: #f6f7f9; cursor: pointer; }
.fwb-tl-head button:hover { background: #eceff3; }
.fwb-tl-deg { min-width: 36px; text-align: right; color: ${COLORS.textDim}; font-variant-numeric: tabular-nums; }
.fwb-tl-head-label { color: ${COLORS.textDim}; }
`;

// head pose sliders: [trait index, name, min, max, tooltip]; degrees about the model's axes
const HEAD_ANGLES = [
  [0, "yaw", -180, 180, "Yaw: turn about the model's up axis (+: toward the subject's left)"],
  [1, "pitch", -90, 90, "Pitch: nod about the side axis (+: down)"],
  [2, "roll", -180, 180, "Roll: tilt about the front axis (+: top of the head to the subject's right)"],
];

function el(tag, attrs = {}, children = []) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") e.className = v;
    else if (k === "text") e.textContent = v;
    else e.setAttribute(k, v);
  }
  for (const c of children) e.appendChild(c);
  return e;
}

// PNG bytes of a `_thumbnails` value: a DataView (ipywidgets' binary buffers) or any view
function asBytes(v) {
  if (!v) return null;
  if (v instanceof Uint8Array) return v;
  if (v instanceof ArrayBuffer) return new Uint8Array(v);
  if (ArrayBuffer.isView(v)) return new Uint8Array(v.buffer, v.byteOffset, v.byteLength);
  return null;
}

function sameBytes(a, b) {
  if (a.length !== b.length) return false;
  for (let i = 0; i < a.length; i++) if (a[i] !== b[i]) return false;
  return true;
}

function fmtTime(t) {
  return `${t.toFixed(2)} s`;
}

function clamp(x, a, b) {
  return Math.min(Math.max(x, a), b);
}

class TimelineView {
  constructor(model, root) {
    this.model = model;
    this.root = root;
    this.selected = []; // [[track, index], ...] (mirrors the `selected_keys` trait)
    this.drag = null; // current pointer gesture in the main canvas
    this.curveDrag = null; // current tangent drag in the curve view
    this.dropTime = null; // HTML5 drag-over position (seconds) or null
    this.scrub = { seq: 0, inflight: null, pending: null, sentAt: 0, sent: 0 };
    this.draws = 0;
    this.raf = 0;
    this.geom = null; // last layout, for hit tests and hooks
    this.disposers = [];
    this.thumbs = new Map(); // name -> {bytes, url}: object URLs of the chip pictures
    this.thumbsRaw = undefined; // the `_thumbnails` value they were made from
    this.build();
    this.bind();
    this.sync();
  }

  // ------------------------------------------------------------------ DOM
  build() {
    const r = this.root;
    r.classList.add("fwb-timeline");
    r.setAttribute("tabindex", "0");
    if (!document.getElementById("fwb-timeline-css")) {
      const s = el("style", { id: "fwb-timeline-css" });
      s.textContent = CSS;
      document.head.appendChild(s);
    }
    const b = (cls, text, title) => el("button", { class: cls, text, title, type: "button" });
    this.btnStart = b("fwb-tl-start", "|◀", "Go to the start of the range");
    this.btnPlay = b("fwb-tl-play", "▶ Play", "Play from the playhead (kernel-driven)");
    this.btnPause = b("fwb-tl-pause", "‖ Pause", "Pause playback");
    this.chkLoop = el("input", { type: "checkbox", class: "fwb-tl-loop" });
    const loopLabel = el("label", { title: "Loop playback" }, [this.chkLoop, el("span", { text: "Loop" })]);
    this.inpFps = el("input", { type: "number", class: "fwb-tl-fps", min: "1", max: "240", step: "1" });
    const fpsLabel = el("label", { title: "Timeline frame rate (undoable)" }, [
      el("span", { text: "fps" }),
      this.inpFps,
    ]);
    this.btnKey = b("fwb-tl-key", "◆ Key", "Key the current weights at the playhead");
    this.btnKeyHandles = b("fwb-tl-key-handles", "◆ Key handles", "Key the handle offsets at the playhead");
    this.btnDelete = b("fwb-tl-delete", "✕ Delete", "Delete the selected keys (Delete/Backspace)");
    this.selInterp = el("select", { class: "fwb-tl-interp", title: "Interpolation of the selected keys" });
    for (const v of ["", "step", "linear", "bezier"]) {
      this.selInterp.appendChild(el("option", { value: v, text: v || "interp…" }));
    }
    this.btnGallery = b(
      "fwb-tl-key-gallery",
      "◆ Key selected expression at playhead",
      "Key the expression selected in the gallery at the playhead",
    );
    this.status = el("span", { class: "fwb-tl-status" });
    this.toolbar = el("div", { class: "fwb-tl-toolbar" }, [
      this.btnStart, this.btnPlay, this.btnPause, loopLabel, fpsLabel,
      el("span", { class: "fwb-tl-sep" }),
      this.btnKey, this.btnKeyHandles, this.btnDelete, this.selInterp,
      el("span", { class: "fwb-tl-sep" }),
      this.btnGallery, this.status,
    ]); // prettier-ignore
    // head pose: yaw/pitch/roll sliders + key button (their own row)
    this.headInputs = [];
    const headParts = [el("span", { class: "fwb-tl-head-label", text: "Head pose" })];
    for (const [, name, lo, hi, title] of HEAD_ANGLES) {
      const inp = el("input", { type: "range", class: `fwb-tl-${name}`, min: String(lo), max: String(hi), step: "1" });
      const out = el("span", { class: "fwb-tl-deg", text: "0°" });
      this.headInputs.push({ inp, out });
      headParts.push(el("label", { title }, [el("span", { text: name }), inp, out]));
    }
    this.btnKeyHead = b("fwb-tl-key-head", "◆ Key head pose", "Key the head's yaw/pitch/roll at the playhead");
    this.poseDirty = false; // the sliders hold an edit not keyed yet
    this.headBox = el("div", { class: "fwb-tl-head" }, [...headParts, this.btnKeyHead]);
    this.chips = el("div", { class: "fwb-tl-chips" });
    this.canvas = el("canvas", { class: "fwb-tl-canvas" });
    this.curveCanvas = el("canvas", { class: "fwb-tl-curve-canvas" });
    this.curveBox = el("div", { class: "fwb-tl-curve-box" }, [this.curveCanvas]);
    r.append(this.toolbar, this.headBox, this.chips, this.canvas, this.curveBox);
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
    for (const name of ["_tracks", "_curve", "playing", "loop", "status", "_error", "expressions",
      "_saved_expressions", "_thumbnails", "_gallery_selected", "selected_keys", "selected_track", "_has_handles",
      "_head_pose"]) {
      m.on(`change:${name}`, redraw);
      this.disposers.push(() => m.off(`change:${name}`, redraw));
    }
    const onMsg = (msg) => this.onMessage(msg);
    m.on("msg:custom", onMsg);
    this.disposers.push(() => m.off("msg:custom", onMsg));

    this.on(this.btnStart, "click", () => this.send({ type: "scrub", time: this.state().start, seq: -1 }));
    this.on(this.btnPlay, "click", () => this.send({ type: "play" }));
    this.on(this.btnPause, "click", () => this.send({ type: "pause" }));
    this.on(this.chkLoop, "change", () => {
      m.set("loop", this.chkLoop.checked);
      m.save_changes();
    });
    this.on(this.inpFps, "change", () => {
      const v = Number(this.inpFps.value);
      if (Number.isFinite(v) && v > 0) this.send({ type: "set_fps", fps: v });
    });
    this.on(this.btnKey, "click", () => this.send({ type: "key" }));
    this.on(this.btnKeyHandles, "click", () => this.send({ type: "key_handles" }));
    for (const { inp, out } of this.headInputs) {
      this.on(inp, "input", () => {
        out.textContent = `${Number(inp.value).toFixed(0)}°`;
        this.poseDirty = true;
        this.root.setAttribute("data-head-pose", JSON.stringify(this.headAngles()));
      });
    }
    this.on(this.btnKeyHead, "click", () => {
      const [yaw, pitch, roll] = this.headAngles();
      this.poseDirty = false;
      this.send({ type: "key_head_pose", yaw, pitch, roll });
    });
    this.on(this.btnDelete, "click", () => this.deleteSelected());
    this.on(this.selInterp, "change", () => {
      const v = this.selInterp.value;
      if (v && this.selected.length) this.send({ type: "set_interpolation", keys: this.selected, interpolation: v });
    });
    this.on(this.btnGallery, "click", () => this.send({ type: "key_gallery" }));
    this.on(this.root, "keydown", (e) => this.onKey(e));

    // main canvas: scrub, select, drag keys, double-click to add
    const c = this.canvas;
    this.on(c, "pointerdown", (e) => this.onDown(e));
    this.on(c, "pointermove", (e) => this.onMove(e));
    this.on(c, "pointerup", (e) => this.onUp(e));
    this.on(c, "pointercancel", (e) => this.onUp(e, true));
    this.on(c, "dblclick", (e) => this.onDblClick(e));
    // HTML5 drop of an expression chip
    this.on(c, "dragover", (e) => this.onDragOver(e));
    this.on(c, "dragleave", () => {
      this.dropTime = null;
      this.requestDraw();
    });
    this.on(c, "drop", (e) => this.onDrop(e));
    // curve view: tangent handles
    const cc = this.curveCanvas;
    this.on(cc, "pointerdown", (e) => this.onCurveDown(e));
    this.on(cc, "pointermove", (e) => this.onCurveMove(e));
    this.on(cc, "pointerup", (e) => this.onCurveUp(e));
    this.on(cc, "pointercancel", () => {
      this.curveDrag = null;
      this.requestDraw();
    });
    this.on(cc, "dblclick", (e) => this.onCurveDblClick(e));

    this.resizeObs = new ResizeObserver(() => this.requestDraw());
    this.resizeObs.observe(this.root);
    this.disposers.push(() => this.resizeObs.disconnect());
    // hooks hold client coordinates: refresh them when anything scrolls
    this.on(document, "scroll", () => this.writeHooks(), { capture: true, passive: true });
    this.root.fwbHooks = () => this.writeHooks();
  }

  // Viewports of the same face model draw in draft resolution while a timeline plays
  // (software WebGL only, see softwareWebGL() in viewport/util.js): tell them through the
  // shared playback registry (shared/playback.js) when playback starts/stops.
  announcePlayback(playing) {
    if (playing === !!this.announcedPlaying) return;
    this.announcedPlaying = playing;
    if (!this.playbackId) this.playbackId = `tl-${Math.random().toString(36).slice(2)}`;
    announce(this.playbackId, this.model.get("_scene") || "", playing);
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

  headAngles() {
    return this.headInputs.map(({ inp }) => Number(inp.value));
  }

  // the sliders follow the pose keyed at the playhead, unless they hold an unkeyed edit
  syncHeadPose() {
    const pose = this.model.get("_head_pose") || [0, 0, 0];
    if (!this.poseDirty) {
      this.headInputs.forEach(({ inp, out }, i) => {
        const v = Number(pose[i] || 0);
        if (Number(inp.value) !== v) inp.value = String(v);
        out.textContent = `${v.toFixed(0)}°`;
      });
    }
    this.root.setAttribute("data-head-pose", JSON.stringify(this.headAngles()));
  }

  // --------------------------------------------------------------- state
  state() {
    return this.model.get("_tracks") || { fps: 30, start: 0, end: 0, view: [0, 2], tracks: [] };
  }

  track(name) {
    return this.state().tracks.find((t) => t.name === name) || null;
  }

  sync() {
    const m = this.model;
    const st = this.state();
    const sel = m.get("selected_keys") || [];
    // keep the local selection when Python echoes it back; drop indices that vanished
    this.selected = sel.filter(([tn, i]) => {
      const tr = this.track(tn);
      return tr && i >= 0 && i < tr.times.length;
    });
    if (document.activeElement !== this.inpFps) this.inpFps.value = String(st.fps);
    this.chkLoop.checked = !!m.get("loop");
    const playing = !!m.get("playing");
    this.btnPlay.classList.toggle("fwb-on", playing);
    this.btnPlay.disabled = playing;
    this.btnPause.disabled = !playing;
    this.btnKeyHandles.disabled = !m.get("_has_handles");
    this.btnDelete.disabled = this.selected.length === 0;
    const gsel = m.get("_gallery_selected");
    this.btnGallery.disabled = !gsel;
    this.btnGallery.textContent = gsel ? `◆ Key "${gsel}" at playhead` : "◆ Key selected expression at playhead";
    const err = m.get("_error") || "";
    this.status.textContent = err || m.get("status") || "";
    this.status.classList.toggle("fwb-err", !!err);
    this.root.setAttribute("data-error", err);
    this.root.setAttribute("data-status", m.get("status") || "");
    this.root.setAttribute("data-playing", playing ? "1" : "0");
    this.announcePlayback(playing);
    // interpolation selector shows the common interpolation of the selection
    const kinds = new Set(this.selected.map(([tn, i]) => this.track(tn).interp[i]));
    this.selInterp.value = kinds.size === 1 ? [...kinds][0] : "";
    this.selInterp.disabled = this.selected.length === 0;
    this.syncHeadPose();
    this.syncChips();
    this.requestDraw();
  }

  // object URLs of the chip pictures, remade only for PNGs whose bytes changed
  syncThumbs() {
    const raw = this.model.get("_thumbnails") || {};
    if (raw === this.thumbsRaw) return false;
    this.thumbsRaw = raw;
    let changed = false;
    const seen = new Set();
    for (const [name, value] of Object.entries(raw)) {
      const bytes = asBytes(value);
      if (!bytes || !bytes.length) continue;
      seen.add(name);
      const old = this.thumbs.get(name);
      if (old && sameBytes(old.bytes, bytes)) continue;
      if (old) URL.revokeObjectURL(old.url);
      const copy = bytes.slice(); // the message buffer may be reused
      this.thumbs.set(name, { bytes: copy, url: URL.createObjectURL(new Blob([copy], { type: "image/png" })) });
      changed = true;
    }
    for (const [name, { url }] of [...this.thumbs]) {
      if (seen.has(name)) continue;
      URL.revokeObjectURL(url);
      this.thumbs.delete(name);
      changed = true;
    }
    return changed;
  }

  syncChips() {
    const thumbsChanged = this.syncThumbs();
    const names = this.model.get("expressions") || [];
    const saved = new Set(this.model.get("_saved_expressions") || []);
    const key = JSON.stringify([names, [...saved]]);
    if (key === this.chipsKey && !thumbsChanged) return;
    this.chipsKey = key;
    const pictures = names.some((n) => this.thumbs.has(n));
    this.chips.classList.toggle("fwb-tl-thumbs", pictures);
    this.chips.replaceChildren(el("span", { class: "fwb-tl-chips-label", text: "Drag onto the timeline:" }));
    let shown = 0;
    for (const n of names) {
      const kind = saved.has(n) ? "saved expression" : "blendshape";
      const chip = el("span", {
        class: "fwb-tl-chip" + (saved.has(n) ? " fwb-saved" : "") + (pictures ? " fwb-tl-thumb" : ""),
        draggable: "true",
        "data-name": n,
        title: `${kind} ${n}: drag onto the timeline to key it`,
      });
      let img = null;
      if (pictures) {
        const th = this.thumbs.get(n);
        if (th) {
          // the chip is dragged, not the picture (whose own drag would carry its URL)
          img = el("img", { src: th.url, alt: n, draggable: "false", width: THUMB, height: THUMB });
          shown += 1;
        }
        chip.append(
          img || el("span", { class: "fwb-tl-noimg", text: saved.has(n) ? "★" : n.slice(0, 1) }),
          el("span", { class: "fwb-tl-chip-name", text: saved.has(n) ? `★ ${n}` : n }),
        );
      } else {
        chip.textContent = n;
      }
      chip.addEventListener("dragstart", (e) => {
        e.dataTransfer.setData("application/x-fwb-expression", n);
        e.dataTransfer.setData("text/plain", n);
        e.dataTransfer.effectAllowed = "copy";
        if (img) e.dataTransfer.setDragImage(img, THUMB / 2, THUMB / 2);
      });
      this.chips.appendChild(chip);
    }
    this.chips.setAttribute("data-thumbs", String(shown));
  }

  onMessage(msg) {
    if (!msg || typeof msg !== "object") return;
    if (msg.type === "frame") {
      // playback flow control: answer once the browser reached its next animation
      // frame, i.e. after the viewport drew the geometry sent before this message
      requestAnimationFrame(() => this.send({ type: "frame_ack", seq: msg.seq }));
      return;
    }
    if (msg.type === "scrub_ack") {
      if (this.scrub.inflight === msg.seq) this.scrub.inflight = null;
      this.flushScrub();
    }
  }

  // -------------------------------------------------------------- layout
  layout() {
    const st = this.state();
    const w = Math.max(this.root.clientWidth - 10, 300);
    const rows = st.tracks.length;
    const h = RULER + Math.max(rows, 1) * ROW + 6;
    const [v0, v1] = st.view;
    const x0 = GUTTER;
    const x1 = w - RIGHT_PAD;
    return {
      w, h, v0, v1, x0, x1,
      tx: (t) => x0 + ((t - v0) / (v1 - v0)) * (x1 - x0),
      xt: (x) => v0 + ((x - x0) / (x1 - x0)) * (v1 - v0),
      rowY: (i) => RULER + i * ROW + ROW / 2,
    }; // prettier-ignore
  }

  snap(t) {
    const fps = this.state().fps;
    return Math.round(t * fps) / fps;
  }

  localXY(e, canvas) {
    const r = canvas.getBoundingClientRect();
    return [e.clientX - r.left, e.clientY - r.top];
  }

  hitKey(x, y) {
    const g = this.geom;
    if (!g) return null;
    const st = this.state();
    let best = null;
    let bestD = KEY_R + 3;
    st.tracks.forEach((tr, row) => {
      const ky = g.rowY(row);
      if (Math.abs(y - ky) > KEY_R + 3) return;
      tr.times.forEach((t, i) => {
        const d = Math.abs(g.tx(t) - x);
        if (d <= bestD) {
          bestD = d;
          best = { track: tr.name, index: i, row, time: t };
        }
      });
    });
    return best;
  }

  rowAt(y) {
    const st = this.state();
    const i = Math.floor((y - RULER) / ROW);
    return y >= RULER && i >= 0 && i < st.tracks.length ? i : -1;
  }

  isSelected(track, index) {
    return this.selected.some(([t, i]) => t === track && i === index);
  }

  setSelection(sel, track) {
    this.selected = sel;
    this.model.set("selected_keys", sel);
    if (track !== undefined) this.model.set("selected_track", track);
    this.model.save_changes();
    this.sync();
  }

  // ------------------------------------------------------------ scrubbing
  scrubTo(t) {
    const st = this.state();
    this.scrub.pending = clamp(t, st.view[0], st.view[1]);
    this.scrub.local = this.scrub.pending;
    this.requestDraw(false);
    this.flushScrub();
  }

  flushScrub() {
    const s = this.scrub;
    const now = performance.now();
    if (s.inflight !== null && now - s.sentAt < ACK_TIMEOUT_MS) return; // one in flight
    if (s.pending === null) return;
    s.seq += 1;
    s.inflight = s.seq;
    s.sentAt = now;
    s.sent += 1;
    this.send({ type: "scrub", time: s.pending, seq: s.seq });
    s.pending = null;
    this.root.setAttribute("data-scrub-sent", String(s.sent));
  }

  // -------------------------------------------------------- main pointer
  onDown(e) {
    if (e.button !== 0) return;
    this.root.focus({ preventScroll: true });
    const [x, y] = this.localXY(e, this.canvas);
    const g = this.geom;
    if (!g) return;
    this.canvas.setPointerCapture(e.pointerId);
    const playX = g.tx(this.model.get("time"));
    if (y < RULER || (Math.abs(x - playX) < 4 && x >= g.x0)) {
      if (x < g.x0 - 4) return;
      this.drag = { kind: "scrub" };
      this.send({ type: "scrub_start" });
      this.scrubTo(this.snap(g.xt(x)));
      return;
    }
    const hit = this.hitKey(x, y);
    if (hit) {
      let sel = this.selected;
      if (e.shiftKey) {
        sel = this.isSelected(hit.track, hit.index)
          ? sel.filter(([t, i]) => !(t === hit.track && i === hit.index))
          : [...sel, [hit.track, hit.index]];
      } else if (!this.isSelected(hit.track, hit.index)) {
        sel = [[hit.track, hit.index]];
      }
      this.setSelection(sel, hit.track);
      this.drag = { kind: "key", hit, x0: x, moved: false, time: hit.time };
      return;
    }
    const row = this.rowAt(y);
    this.drag = null;
    this.setSelection(e.shiftKey ? this.selected : [], row >= 0 ? this.state().tracks[row].name : undefined);
  }

  onMove(e) {
    const d = this.drag;
    if (!d || !this.geom) return;
    const [x] = this.localXY(e, this.canvas);
    if (d.kind === "scrub") {
      this.scrubTo(this.snap(this.geom.xt(x)));
    } else if (d.kind === "key") {
      if (!d.moved && Math.abs(x - d.x0) < DRAG_START_PX) return;
      d.moved = true;
      const st = this.state();
      d.time = this.snap(Math.max(this.geom.xt(x), st.view[0]));
      this.requestDraw();
    }
  }

  onUp(e, cancelled = false) {
    const d = this.drag;
    this.drag = null;
    if (this.canvas.hasPointerCapture(e.pointerId)) this.canvas.releasePointerCapture(e.pointerId);
    if (!d) return;
    if (d.kind === "scrub") {
      this.scrub.local = null;
      this.send({ type: "scrub_end" });
    } else if (d.kind === "key" && d.moved && !cancelled && Math.abs(d.time - d.hit.time) > 1e-9) {
      this.send({ type: "move_key", track: d.hit.track, index: d.hit.index, time: d.time });
    }
    this.requestDraw();
  }

  onDblClick(e) {
    const [x, y] = this.localXY(e, this.canvas);
    const g = this.geom;
    if (!g || x < g.x0 || this.hitKey(x, y)) return;
    const row = this.rowAt(y);
    if (row < 0) return;
    this.send({ type: "add_key", track: this.state().tracks[row].name, time: this.snap(g.xt(x)) });
  }

  onKey(e) {
    if (e.target !== this.root && e.target !== this.canvas && e.target !== this.curveCanvas) return;
    if (e.key === "Delete" || e.key === "Backspace") {
      this.deleteSelected();
    } else if (e.key === "ArrowLeft" || e.key === "ArrowRight") {
      const dt = (e.key === "ArrowLeft" ? -1 : 1) / this.state().fps;
      this.send({ type: "scrub", time: this.snap(this.model.get("time") + dt), seq: -1 });
    } else {
      return;
    }
    // keep JupyterLab's notebook shortcuts from acting on the same key
    e.preventDefault();
    e.stopPropagation();
  }

  deleteSelected() {
    if (!this.selected.length) return;
    this.send({ type: "delete_keys", keys: this.selected });
  }

  // ---------------------------------------------------------- HTML5 drop
  acceptsDrop(e) {
    const types = Array.from((e.dataTransfer && e.dataTransfer.types) || []);
    return types.includes("application/x-fwb-expression") || types.includes("text/plain");
  }

  onDragOver(e) {
    if (!this.acceptsDrop(e) || !this.geom) return;
    e.preventDefault();
    e.dataTransfer.dropEffect = "copy";
    const [x] = this.localXY(e, this.canvas);
    this.dropTime = this.snap(Math.max(this.geom.xt(x), this.state().view[0]));
    this.requestDraw();
  }

  onDrop(e) {
    if (!this.acceptsDrop(e) || !this.geom) return;
    e.preventDefault();
    const name =
      e.dataTransfer.getData("application/x-fwb-expression") || e.dataTransfer.getData("text/plain");
    const [x] = this.localXY(e, this.canvas);
    const t = this.snap(Math.max(this.geom.xt(x), this.state().view[0]));
    this.dropTime = null;
    this.requestDraw();
    if (name) this.send({ type: "key_expression", name, time: t });
  }

  // ---------------------------------------------------------- curve view
  curveTrack() {
    const name = this.model.get("selected_track");
    const tr = name ? this.track(name) : null;
    return tr && tr.values ? tr : null;
  }

  curveLayout(tr) {
    const g = this.geom;
    const curve = this.model.get("_curve") || {};
    let lo = 0;
    let hi = 1;
    const vals = [...(curve.values || []), ...tr.values];
    for (const h of this.tangentHandles(tr, null)) vals.push(h.v);
    for (const v of vals) {
      lo = Math.min(lo, v);
      hi = Math.max(hi, v);
    }
    const pad = 0.08 * (hi - lo || 1);
    lo -= pad;
    hi += pad;
    const top = 8;
    const bottom = CURVE_H - 16;
    return {
      lo, hi, top, bottom,
      vy: (v) => bottom - ((v - lo) / (hi - lo)) * (bottom - top),
      yv: (y) => lo + ((bottom - y) / (bottom - top)) * (hi - lo),
      tx: g.tx, xt: g.xt,
    }; // prettier-ignore
  }

  // Bézier control points of the key's tangents: at 1/3 of the neighbouring interval
  // in time (the model's Hermite <-> Bézier convention, see workbench/tracks.py).
  tangentHandles(tr, override) {
    const out = [];
    const n = tr.times.length;
    for (let i = 0; i < n; i++) {
      const t = tr.times[i];
      const v = tr.values[i];
      let mIn = tr.in[i];
      let mOut = tr.out[i];
      if (override && override.index === i) {
        if (override.side === "in" || override.aligned) mIn = override.slope;
        if (override.side === "out" || override.aligned) mOut = override.slope;
      }
      if (i > 0 && tr.interp[i - 1] === "bezier") {
        const d = (t - tr.times[i - 1]) / 3;
        out.push({ index: i, side: "in", t: t - d, v: v - mIn * d, user: tr.mode[i] === "user" });
      }
      if (i < n - 1 && tr.interp[i] === "bezier") {
        const d = (tr.times[i + 1] - t) / 3;
        out.push({ index: i, side: "out", t: t + d, v: v + mOut * d, user: tr.mode[i] === "user" });
      }
    }
    return out;
  }

  hitHandle(x, y) {
    const tr = this.curveTrack();
    if (!tr || !this.geom) return null;
    const cl = this.curveLayout(tr);
    let best = null;
    let bestD = HANDLE_R + 4;
    for (const h of this.tangentHandles(tr, null)) {
      const d = Math.hypot(cl.tx(h.t) - x, cl.vy(h.v) - y);
      if (d <= bestD) {
        bestD = d;
        best = h;
      }
    }
    return best;
  }

  onCurveDown(e) {
    if (e.button !== 0) return;
    this.root.focus({ preventScroll: true });
    const [x, y] = this.localXY(e, this.curveCanvas);
    const h = this.hitHandle(x, y);
    if (!h) return;
    const tr = this.curveTrack();
    this.curveCanvas.setPointerCapture(e.pointerId);
    this.curveDrag = { track: tr.name, index: h.index, side: h.side, aligned: !e.altKey, slope: null, tr };
  }

  slopeAt(d, x, y) {
    const tr = d.tr;
    const cl = this.curveLayout(tr);
    const tk = tr.times[d.index];
    const vk = tr.values[d.index];
    let dt = cl.xt(x) - tk;
    // the handle stays on its side of the key (time of a Bézier handle is fixed at 1/3)
    const minDt = 1e-3;
    dt = d.side === "out" ? Math.max(dt, minDt) : Math.min(dt, -minDt);
    return (cl.yv(y) - vk) / dt;
  }

  onCurveMove(e) {
    const d = this.curveDrag;
    if (!d) return;
    const [x, y] = this.localXY(e, this.curveCanvas);
    d.slope = this.slopeAt(d, x, y);
    this.requestDraw();
  }

  onCurveUp(e) {
    const d = this.curveDrag;
    this.curveDrag = null;
    if (this.curveCanvas.hasPointerCapture(e.pointerId)) this.curveCanvas.releasePointerCapture(e.pointerId);
    if (d && d.slope !== null && Number.isFinite(d.slope)) {
      this.send({ type: "set_tangent", track: d.track, index: d.index, side: d.side, slope: d.slope, aligned: d.aligned });
    }
    this.requestDraw();
  }

  onCurveDblClick(e) {
    const [x, y] = this.localXY(e, this.curveCanvas);
    const h = this.hitHandle(x, y);
    const tr = this.curveTrack();
    if (h && tr) this.send({ type: "auto_tangent", track: tr.name, index: h.index });
  }

  // ------------------------------------------------------------- drawing
  // base = false: only the playhead moved, the cached track/curve layers are reused
  requestDraw(base = true) {
    this.baseDirty = this.baseDirty || base;
    if (this.raf) return;
    this.raf = requestAnimationFrame(() => {
      this.raf = 0;
      this.draw();
    });
  }

  prepCanvas(canvas, w, h) {
    const dpr = window.devicePixelRatio || 1;
    if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
      canvas.width = Math.round(w * dpr);
      canvas.height = Math.round(h * dpr);
    }
    if (canvas.style.height !== `${h}px`) canvas.style.height = `${h}px`;
    const ctx = canvas.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, w, h);
    return ctx;
  }

  tickStep(pxPerSec, fps) {
    // frame ticks when they are at least 5 px apart, else every n frames
    let frames = 1;
    for (const n of [1, 2, 5, 10, 15, 30, 60, 120, 300, 600]) {
      frames = n;
      if ((n / fps) * pxPerSec >= 5) break;
    }
    return frames;
  }

  draw() {
    this.draws += 1;
    const g = this.layout();
    this.geom = g;
    const size = `${g.w}x${g.h}@${window.devicePixelRatio || 1}`;
    if (this.baseDirty || size !== this.baseSize || !this.mainBase) {
      this.mainBase = this.mainBase || document.createElement("canvas");
      this.curveBase = this.curveBase || document.createElement("canvas");
      this.drawBase(g);
      this.drawCurve(g);
      this.baseDirty = false;
      this.baseSize = size;
    }
    const ctx = this.prepCanvas(this.canvas, g.w, g.h);
    ctx.drawImage(this.mainBase, 0, 0, g.w, g.h);
    this.drawPlayhead(ctx, g);
    const cctx = this.prepCanvas(this.curveCanvas, g.w, CURVE_H);
    cctx.drawImage(this.curveBase, 0, 0, g.w, CURVE_H);
    if (this.curveTrack()) {
      const px = Math.round(g.tx(this.playheadTime())) + 0.5;
      cctx.strokeStyle = COLORS.playhead;
      cctx.beginPath();
      cctx.moveTo(px, 0);
      cctx.lineTo(px, CURVE_H);
      cctx.stroke();
    }
    this.writeHooks();
  }

  // rows, ruler, keys: redrawn only when the state, the size or a drag preview changes
  drawBase(g) {
    const st = this.state();
    const ctx = this.prepCanvas(this.mainBase, g.w, g.h);
    ctx.font = "11px system-ui, sans-serif";
    ctx.textBaseline = "middle";
    ctx.fillStyle = COLORS.bg;
    ctx.fillRect(0, 0, g.w, g.h);
    // rows
    const selTrack = this.model.get("selected_track");
    st.tracks.forEach((tr, i) => {
      const y = RULER + i * ROW;
      ctx.fillStyle = tr.name === selTrack ? COLORS.rowSel : i % 2 ? COLORS.rowAlt : COLORS.bg;
      ctx.fillRect(0, y, g.w, ROW);
      ctx.fillStyle = COLORS.text;
      ctx.fillText(tr.label, 6, y + ROW / 2, GUTTER - 12);
    });
    if (!st.tracks.length) {
      ctx.fillStyle = COLORS.textDim;
      ctx.fillText("No keys yet: press Key, or drag an expression chip here", g.x0 + 6, RULER + ROW / 2);
    }
    // ruler + frame ticks
    ctx.fillStyle = COLORS.ruler;
    ctx.fillRect(0, 0, g.w, RULER);
    const fps = st.fps;
    const pxPerSec = (g.x1 - g.x0) / (g.v1 - g.v0);
    const every = this.tickStep(pxPerSec, fps);
    const major = every * (fps >= 1 ? Math.max(1, Math.round(fps / every)) : 1); // about one per second
    const f0 = Math.ceil(g.v0 * fps / every) * every;
    for (let f = f0; f / fps <= g.v1 + 1e-9; f += every) {
      const x = Math.round(g.tx(f / fps)) + 0.5;
      const isMajor = f % major === 0;
      ctx.strokeStyle = isMajor ? COLORS.gridMajor : COLORS.grid;
      ctx.beginPath();
      ctx.moveTo(x, isMajor ? 4 : RULER - 7);
      ctx.lineTo(x, RULER);
      if (isMajor) {
        ctx.moveTo(x, RULER);
        ctx.lineTo(x, g.h);
      }
      ctx.stroke();
      if (isMajor) {
        ctx.fillStyle = COLORS.textDim;
        ctx.fillText(`${(f / fps).toFixed(f % fps === 0 ? 0 : 2)}s`, x + 3, 9);
      }
    }
    // playback range
    ctx.fillStyle = "rgba(31,111,229,0.10)";
    ctx.fillRect(g.tx(st.start), RULER - 4, Math.max(g.tx(st.end) - g.tx(st.start), 1), 4);
    ctx.fillStyle = COLORS.textDim;
    ctx.fillText(`${fps} fps`, 6, RULER / 2);
    // keys
    const d = this.drag;
    st.tracks.forEach((tr, row) => {
      const y = RULER + row * ROW + ROW / 2;
      tr.times.forEach((t, i) => {
        let tt = t;
        const dragged = d && d.kind === "key" && d.moved && d.hit.track === tr.name && d.hit.index === i;
        if (dragged) tt = d.time;
        this.diamond(ctx, g.tx(tt), y, tr.interp[i], this.isSelected(tr.name, i), dragged);
      });
    });
    // drop indicator
    if (this.dropTime !== null) {
      const x = g.tx(this.dropTime);
      ctx.strokeStyle = COLORS.drop;
      ctx.setLineDash([4, 3]);
      ctx.beginPath();
      ctx.moveTo(x, 0);
      ctx.lineTo(x, g.h);
      ctx.stroke();
      ctx.setLineDash([]);
    }
  }

  drawPlayhead(ctx, g) {
    ctx.font = "11px system-ui, sans-serif";
    ctx.textBaseline = "middle";
    const t = this.playheadTime();
    const px = Math.round(g.tx(t)) + 0.5;
    ctx.strokeStyle = COLORS.playhead;
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    ctx.moveTo(px, 0);
    ctx.lineTo(px, g.h);
    ctx.stroke();
    ctx.lineWidth = 1;
    ctx.fillStyle = COLORS.playhead;
    ctx.beginPath();
    ctx.moveTo(px - 6, 0);
    ctx.lineTo(px + 6, 0);
    ctx.lineTo(px + 6, 10);
    ctx.lineTo(px, 16);
    ctx.lineTo(px - 6, 10);
    ctx.closePath();
    ctx.fill();
    ctx.fillStyle = COLORS.text;
    ctx.fillText(fmtTime(t), Math.min(px + 9, g.w - 52), RULER - 7);
  }

  playheadTime() {
    const local = this.drag && this.drag.kind === "scrub" ? this.scrub.local : null;
    return local !== null && local !== undefined ? local : this.model.get("time");
  }

  diamond(ctx, x, y, interp, selected, dragged) {
    ctx.beginPath();
    if (interp === "step") {
      ctx.rect(x - KEY_R + 1, y - KEY_R + 1, 2 * KEY_R - 2, 2 * KEY_R - 2);
    } else {
      ctx.moveTo(x, y - KEY_R);
      ctx.lineTo(x + KEY_R, y);
      ctx.lineTo(x, y + KEY_R);
      ctx.lineTo(x - KEY_R, y);
      ctx.closePath();
    }
    ctx.fillStyle = selected ? COLORS.keySel : interp === "linear" ? COLORS.keyLinear : interp === "step" ? COLORS.keyStep : COLORS.key;
    ctx.globalAlpha = dragged ? 0.75 : 1;
    ctx.fill();
    ctx.globalAlpha = 1;
    ctx.strokeStyle = selected ? "#0b3d91" : COLORS.keyStroke;
    ctx.stroke();
  }

  drawCurve(g) {
    const tr = this.curveTrack();
    const w = g.w;
    const ctx = this.prepCanvas(this.curveBase, w, CURVE_H);
    ctx.font = "11px system-ui, sans-serif";
    ctx.textBaseline = "middle";
    ctx.fillStyle = COLORS.bg;
    ctx.fillRect(0, 0, w, CURVE_H);
    this.tangentHooks = [];
    if (!tr) {
      ctx.fillStyle = COLORS.textDim;
      const name = this.model.get("selected_track");
      ctx.fillText(
        name ? `${name}: no curve view for vector tracks` : "Curve view: select a weight track (click its row or a key)",
        8, CURVE_H / 2,
      ); // prettier-ignore
      return;
    }
    const cl = this.curveLayout(tr);
    // value grid: 0 and 1 lines
    ctx.strokeStyle = COLORS.grid;
    for (const v of [0, 0.5, 1]) {
      if (v < cl.lo || v > cl.hi) continue;
      const y = Math.round(cl.vy(v)) + 0.5;
      ctx.beginPath();
      ctx.moveTo(g.x0, y);
      ctx.lineTo(g.x1, y);
      ctx.stroke();
      ctx.fillStyle = COLORS.textDim;
      ctx.fillText(v.toFixed(1), g.x0 - 24, y);
    }
    ctx.fillStyle = COLORS.text;
    ctx.fillText(tr.label, 6, 12, GUTTER - 12);
    ctx.fillStyle = COLORS.textDim;
    ctx.fillText("drag a handle: tangent", 6, 30, GUTTER - 12);
    ctx.fillText("Alt: one side only", 6, 44, GUTTER - 12);
    ctx.fillText("double-click: auto", 6, 58, GUTTER - 12);
    // the curve, sampled by Python (the model's own interpolation)
    const curve = this.model.get("_curve") || {};
    if (curve.track === tr.name && curve.times && curve.times.length) {
      ctx.strokeStyle = COLORS.curve;
      ctx.lineWidth = 1.5;
      ctx.beginPath();
      curve.times.forEach((t, i) => {
        const x = g.tx(t);
        const y = cl.vy(curve.values[i]);
        if (i === 0) ctx.moveTo(x, y);
        else ctx.lineTo(x, y);
      });
      ctx.stroke();
      ctx.lineWidth = 1;
    }
    // tangent handles (Bézier segments only) and keys
    const dd = this.curveDrag;
    const override = dd && dd.track === tr.name && dd.slope !== null ? dd : null;
    const handles = this.tangentHandles(tr, override);
    for (const h of handles) {
      const kx = g.tx(tr.times[h.index]);
      const ky = cl.vy(tr.values[h.index]);
      const hx = g.tx(h.t);
      const hy = cl.vy(h.v);
      ctx.strokeStyle = h.user ? COLORS.handleUser : COLORS.handleAuto;
      ctx.beginPath();
      ctx.moveTo(kx, ky);
      ctx.lineTo(hx, hy);
      ctx.stroke();
      ctx.fillStyle = h.user ? COLORS.handleUser : "#fff";
      ctx.beginPath();
      ctx.arc(hx, hy, HANDLE_R - 1, 0, 2 * Math.PI);
      ctx.fill();
      ctx.stroke();
      this.tangentHooks.push([tr.name, h.index, h.side, hx, hy]); // canvas coordinates
    }
    tr.times.forEach((t, i) => {
      this.diamond(ctx, g.tx(t), cl.vy(tr.values[i]), tr.interp[i], this.isSelected(tr.name, i), false);
    });
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

export default {
  render({ model, el }) {
    const view = new TimelineView(model, el);
    return () => view.dispose();
  },
};
