// Key editing in the main canvas: selection, key drag, scrub start, double-click to key,
// Delete/Backspace and the arrow keys. A key drag is previewed locally (the diamond
// follows the pointer) and sent once on release ({type: "move_key", track, index, time}):
// one undo step in the model, nothing sent while dragging. Methods of TimelineView.

import { DRAG_START_PX, KEY_R, ROW, RULER } from "./style.js";

export const keyMethods = {
  bindKeys() {
    const c = this.canvas;
    this.on(c, "pointerdown", (e) => this.onDown(e));
    this.on(c, "pointermove", (e) => this.onMove(e));
    this.on(c, "pointerup", (e) => this.onUp(e));
    this.on(c, "pointercancel", (e) => this.onUp(e, true));
    this.on(c, "dblclick", (e) => this.onDblClick(e));
    this.on(this.root, "keydown", (e) => this.onKey(e));
  },

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
  },

  rowAt(y) {
    const st = this.state();
    const i = Math.floor((y - RULER) / ROW);
    return y >= RULER && i >= 0 && i < st.tracks.length ? i : -1;
  },

  isSelected(track, index) {
    return this.selected.some(([t, i]) => t === track && i === index);
  },

  setSelection(sel, track) {
    this.selected = sel;
    this.model.set("selected_keys", sel);
    if (track !== undefined) this.model.set("selected_track", track);
    this.model.save_changes();
    this.sync();
  },

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
      this.scrubBegin(this.snap(g.xt(x)));
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
  },

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
  },

  onUp(e, cancelled = false) {
    const d = this.drag;
    this.drag = null;
    if (this.canvas.hasPointerCapture(e.pointerId)) this.canvas.releasePointerCapture(e.pointerId);
    if (!d) return;
    if (d.kind === "scrub") {
      this.scrubEnd();
    } else if (d.kind === "key" && d.moved && !cancelled && Math.abs(d.time - d.hit.time) > 1e-9) {
      this.send({ type: "move_key", track: d.hit.track, index: d.hit.index, time: d.time });
    }
    this.requestDraw();
  },

  onDblClick(e) {
    const [x, y] = this.localXY(e, this.canvas);
    const g = this.geom;
    if (!g || x < g.x0 || this.hitKey(x, y)) return;
    const row = this.rowAt(y);
    if (row < 0) return;
    this.send({ type: "add_key", track: this.state().tracks[row].name, time: this.snap(g.xt(x)) });
  },

  onKey(e) {
    if (e.target !== this.root && e.target !== this.canvas && e.target !== this.curveCanvas) return;
    if (e.key === "Delete" || e.key === "Backspace") {
      this.deleteSelected();
    } else if (e.key === "ArrowLeft" || e.key === "ArrowRight") {
      const dt = (e.key === "ArrowLeft" ? -1 : 1) / this.state().fps;
      this.jumpTo(this.snap(this.model.get("time") + dt));
    } else {
      return;
    }
    // keep JupyterLab's notebook shortcuts from acting on the same key
    e.preventDefault();
    e.stopPropagation();
  },

  deleteSelected() {
    if (!this.selected.length) return;
    this.send({ type: "delete_keys", keys: this.selected });
  },

};
