// The timeline's DOM: toolbar (transport, fps, key buttons, interpolation, status), the
// head-pose row (yaw/pitch/roll sliders + "Key head pose"), the chip strip and the two
// canvases; the toolbar's and sliders' listeners and their state from the model's traits.
// Methods of TimelineView (./view.js).

import { injectCss } from "./style.js";

// head pose sliders: [trait index, name, min, max, tooltip]; degrees about the model's axes
const HEAD_ANGLES = [
  [0, "yaw", -180, 180, "Yaw: turn about the model's up axis (+: toward the subject's left)"],
  [1, "pitch", -90, 90, "Pitch: nod about the side axis (+: down)"],
  [2, "roll", -180, 180, "Roll: tilt about the front axis (+: top of the head to the subject's right)"],
];

export function el(tag, attrs = {}, children = []) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") e.className = v;
    else if (k === "text") e.textContent = v;
    else e.setAttribute(k, v);
  }
  for (const c of children) e.appendChild(c);
  return e;
}

export const toolbarMethods = {
  build() {
    const r = this.root;
    r.classList.add("fwb-timeline");
    r.setAttribute("tabindex", "0");
    injectCss();
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
  },

  // buttons, fps field, loop checkbox, interpolation selector, head-pose sliders
  bindToolbar() {
    const m = this.model;
    this.on(this.btnStart, "click", () => this.jumpTo(this.state().start));
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
  },

  // the toolbar's state from the traits (called by sync())
  syncToolbar() {
    const m = this.model;
    if (document.activeElement !== this.inpFps) this.inpFps.value = String(this.state().fps);
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
    // interpolation selector shows the common interpolation of the selection
    const kinds = new Set(this.selected.map(([tn, i]) => this.track(tn).interp[i]));
    this.selInterp.value = kinds.size === 1 ? [...kinds][0] : "";
    this.selInterp.disabled = this.selected.length === 0;
  },

  headAngles() {
    return this.headInputs.map(({ inp }) => Number(inp.value));
  },

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
  },
};
