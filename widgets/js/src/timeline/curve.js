// The curve view: the selected weight track's curve (sampled by Python: `_curve`) with the
// Bézier tangent handles of its keys. Dragging a handle previews the new slope locally and
// sends it once on release ({type: "set_tangent", track, index, side, slope, aligned}; Alt:
// one side only); a double-click sends {type: "auto_tangent"}. Methods of TimelineView.

import { COLORS, CURVE_H, GUTTER, HANDLE_R } from "./style.js";

export const curveMethods = {
  bindCurve() {
    const cc = this.curveCanvas;
    this.on(cc, "pointerdown", (e) => this.onCurveDown(e));
    this.on(cc, "pointermove", (e) => this.onCurveMove(e));
    this.on(cc, "pointerup", (e) => this.onCurveUp(e));
    this.on(cc, "pointercancel", () => {
      this.curveDrag = null;
      this.requestDraw();
    });
    this.on(cc, "dblclick", (e) => this.onCurveDblClick(e));
  },

  curveTrack() {
    const name = this.model.get("selected_track");
    const tr = name ? this.track(name) : null;
    return tr && tr.values ? tr : null;
  },

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
  },

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
  },

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
  },

  onCurveDown(e) {
    if (e.button !== 0) return;
    this.root.focus({ preventScroll: true });
    const [x, y] = this.localXY(e, this.curveCanvas);
    const h = this.hitHandle(x, y);
    if (!h) return;
    const tr = this.curveTrack();
    this.curveCanvas.setPointerCapture(e.pointerId);
    this.curveDrag = { track: tr.name, index: h.index, side: h.side, aligned: !e.altKey, slope: null, tr };
  },

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
  },

  onCurveMove(e) {
    const d = this.curveDrag;
    if (!d) return;
    const [x, y] = this.localXY(e, this.curveCanvas);
    d.slope = this.slopeAt(d, x, y);
    this.requestDraw();
  },

  onCurveUp(e) {
    const d = this.curveDrag;
    this.curveDrag = null;
    if (this.curveCanvas.hasPointerCapture(e.pointerId)) this.curveCanvas.releasePointerCapture(e.pointerId);
    if (d && d.slope !== null && Number.isFinite(d.slope)) {
      this.send({ type: "set_tangent", track: d.track, index: d.index, side: d.side, slope: d.slope, aligned: d.aligned });
    }
    this.requestDraw();
  },

  onCurveDblClick(e) {
    const [x, y] = this.localXY(e, this.curveCanvas);
    const h = this.hitHandle(x, y);
    const tr = this.curveTrack();
    if (h && tr) this.send({ type: "auto_tangent", track: tr.name, index: h.index });
  },

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
  },
};
