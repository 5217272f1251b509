// The main canvas: layout (time <-> x, rows), the ruler with frame ticks, the track rows
// and their key diamonds (squares for step keys), the drop indicator and the playhead.
// The rows/ruler/keys and the curve view are drawn into cached layers; while only the
// playhead moves (playback) just the playhead is drawn over them. Methods of TimelineView.

import { COLORS, CURVE_H, GUTTER, KEY_R, RIGHT_PAD, ROW, RULER } from "./style.js";

function fmtTime(t) {
  return `${t.toFixed(2)} s`;
}

export const trackMethods = {
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
  },

  snap(t) {
    const fps = this.state().fps;
    return Math.round(t * fps) / fps;
  },

  localXY(e, canvas) {
    const r = canvas.getBoundingClientRect();
    return [e.clientX - r.left, e.clientY - r.top];
  },

  // ------------------------------------------------------------- drawing
  // base = false: only the playhead moved, the cached track/curve layers are reused
  requestDraw(base = true) {
    this.baseDirty = this.baseDirty || base;
    if (this.raf) return;
    this.raf = requestAnimationFrame(() => {
      this.raf = 0;
      this.draw();
    });
  },

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
  },

  tickStep(pxPerSec, fps) {
    // frame ticks when they are at least 5 px apart, else every n frames
    let frames = 1;
    for (const n of [1, 2, 5, 10, 15, 30, 60, 120, 300, 600]) {
      frames = n;
      if ((n / fps) * pxPerSec >= 5) break;
    }
    return frames;
  },

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
  },

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
  },

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
  },

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
  },

};
