// Sliders move the face in the browser first (GPU path): the shape sliders Python links to
// the viewport (Viewport.follow_sliders; trait _weight_slider_ids: shape name -> model id)
// are watched here, in the page, and a moved slider's weight goes straight into the
// parameters the views evaluate — no round trip through the kernel before the first pixels.
// The kernel still gets the value (the slider's own comm message) and answers with its
// parameters (and wrinkle rows); those win as soon as they show the slider's value, and a
// value the kernel never confirms (it clamped or refused it) is dropped after LOCAL_MS, by a
// timer when no further message comes. A slider value the kernel itself set (the model moved:
// a scrub, undo, a Python edit) is no prediction: its exact weight is already in the
// kernel's parameters, and the slider's snapped value must not override it.
//
// The weights are made effective as StateView.weight_vector makes them: a muted shape plays 0,
// a derived (corrective) shape plays the product of its drivers clamped to its range
// (workbench.core.families.derive_weights), from _gpu_meta.local = {mute: [shape index],
// products: [[shape, [drivers], lo, hi]]} and _gpu_meta.names (the shapes' order).
//
// Handle drags likewise (predictDrag): the dragged handle's shell offset moves with the
// pointer in the page — by the pointer's motion in the drag plane taken into model space,
// with its mirror reflected in x when the drag is symmetric (HandlesFacet.move) — until the
// kernel's parameters for the drag arrive; _gpu_meta.columns maps handles to basis columns.
// Methods mixed into the Store (./sync.js).
import * as THREE from "three";

const LOCAL_MS = 1500;

export const localWeightMethods = {
  initLocal() {
    this.local = new Map(); // shape index -> { value, t }
    this.sliderModels = [];
    this.onWeightSliders = () => this.followSliders();
    this.model.on("change:_weight_slider_ids", this.onWeightSliders);
    this.followSliders();
  },

  followSliders() {
    for (const [m, fn] of this.sliderModels) m.off("change:value", fn);
    this.sliderModels = [];
    const ids = this.model.get("_weight_slider_ids") || {};
    const manager = this.model.widget_manager;
    if (!manager) return;
    const token = (this.sliderToken = (this.sliderToken || 0) + 1);
    // a slider's model may not exist in the page yet (models load in any order): retry
    const follow = (name, id, tries) => {
      Promise.resolve(manager.get_model(id)).then((m) => {
        if (!m || token !== this.sliderToken) return;
        const fn = () => {
          // a value the kernel set (ipywidgets' _state_lock holds the state it applies) is
          // the kernel's own, exact weight: predicting it from the snapped slider value would
          // override the kernel's parameters with a rounded one (a scrubbed timeline)
          const lock = m._state_lock;
          if (lock && Object.prototype.hasOwnProperty.call(lock, "value")) return;
          this.localWeight(name, Number(m.get("value")));
        };
        m.on("change:value", fn);
        this.sliderModels.push([m, fn]);
      }).catch(() => {
        if (tries > 0 && token === this.sliderToken) setTimeout(() => follow(name, id, tries - 1), 500);
      });
    };
    for (const [name, id] of Object.entries(ids)) follow(name, String(id), 20);
  },

  // A slider moved in the page: play it now.
  localWeight(name, value) {
    const g = this.gpu;
    const meta = this.model.get("_gpu_meta") || {};
    const names = meta.names || [];
    if (!this.gpuMode || !g || !this.gpuParams || this.clipPlay || !Number.isFinite(value)) return;
    const s = names.indexOf(name);
    if (s < 0 || s >= g.k) return;
    const products = (meta.local && meta.local.products) || [];
    if (products.some((r) => r[0] === s)) return; // a derived shape plays its drivers' product
    this.local.set(s, { value, t: performance.now() });
    this.applyLocal(this.gpuParams);
    this.pageParamsChanged();
    this.scheduleLocalExpiry();
  },

  // A prediction the kernel never confirms (it clamped or refused the value, or sent
  // nothing more) ends after LOCAL_MS even when no further message comes: the view goes
  // back to the kernel's last parameters.
  scheduleLocalExpiry() {
    if (this.localTimer) return;
    this.localTimer = setTimeout(() => this.expireLocal(), LOCAL_MS + 50);
  },

  expireLocal() {
    this.localTimer = null;
    if (!this.kernelParams || this.clipPlay || !(this.local.size || this.localMarker)) return;
    this.gpuParams = new Float32Array(this.kernelParams);
    this.reconcileLocal(); // drops what expired, puts the rest back on top
    this.pageParamsChanged();
    if (this.local.size || this.localMarker) this.scheduleLocalExpiry();
  },

  // The page changed the parameters itself (a slider, a drag, a clip frame): every view
  // draws them now, no kernel message involved.
  pageParamsChanged() {
    this.positionsVersion += 1;
    this.lastUpdateTime = performance.now();
    for (const v of this.views) v.paramsChanged?.();
  },

  // A handle drag moved the pointer: `d` the view's drag (index, origin, target), `mirror`
  // the handle it mirrors when the drag is symmetric (or -1). Not predicted (left to the
  // kernel) outside GPU mode or when the handle shares its basis column.
  predictDrag(d, mirror) {
    const g = this.gpu;
    const P = this.gpuParams;
    const cols = (this.model.get("_gpu_meta") || {}).columns || [];
    if (!this.gpuMode || !g || !P || this.clipPlay || cols.length <= d.index) return;
    const share = (c) => cols.filter((x) => x === c).length;
    const col = cols[d.index];
    const colM = mirror >= 0 && mirror < cols.length ? cols[mirror] : -1;
    // a column shared by several handles holds their mean: leave that to the kernel
    if (share(col) !== 1 || (colM >= 0 && (colM === col || share(colM) !== 1))) return;
    const at = (c) => g.k + 3 * c;
    if (!d.local) {
      const M = new THREE.Matrix4().fromArray(P, g.k + 3 * g.hu);
      d.local = {
        u0: new THREE.Vector3(P[at(col)], P[at(col) + 1], P[at(col) + 2]),
        p0: d.origin.clone(),
        toModel: new THREE.Matrix3().setFromMatrix4(M).invert(),
      };
    }
    const L = d.local;
    const u = d.target.clone().sub(L.p0).applyMatrix3(L.toModel).add(L.u0);
    this.localMarker = { col, u: u.toArray(), colM, t: performance.now(), ending: false };
    this.applyLocalMarker(P);
    this.pageParamsChanged();
    this.scheduleLocalExpiry();
  },

  // The drag ended: the kernel's next parameters are final.
  endLocalDrag() {
    if (this.localMarker) this.localMarker.ending = true;
  },

  applyLocalMarker(P) {
    const h = this.localMarker;
    if (!h) return;
    const at = (c) => this.gpu.k + 3 * c;
    for (let q = 0; q < 3; q++) P[at(h.col) + q] = h.u[q];
    if (h.colM >= 0) {
      P[at(h.colM)] = -h.u[0]; P[at(h.colM) + 1] = h.u[1]; P[at(h.colM) + 2] = h.u[2];
    }
  },

  // The kernel's parameters arrived (`P`, effective weights): drop what they confirm, keep
  // the rest on top.
  reconcileLocal() {
    const P = this.gpuParams;
    const h = this.localMarker;
    if (h && P) {
      if (h.ending || performance.now() - h.t > LOCAL_MS || !this.gpu) this.localMarker = null;
      else this.applyLocalMarker(P);
    }
    if (!this.local || !this.local.size || !P) return;
    const now = performance.now();
    const { eff } = this.localRules();
    for (const [s, e] of this.local) {
      if (Math.abs(P[s] - eff.get(s)) < 1e-6 || now - e.t > LOCAL_MS) this.local.delete(s);
    }
    if (this.local.size) this.applyLocal(P);
  },

  // The kernel's rules ({mute: Set of shape indices, products}) and, per locally moved
  // shape, the weight it plays for its slider value.
  localRules() {
    const local = (this.model.get("_gpu_meta") || {}).local || {};
    const mute = new Set(local.mute || []);
    const eff = new Map();
    for (const [s, e] of this.local) eff.set(s, mute.has(s) ? 0 : e.value);
    return { mute, products: local.products || [], eff };
  },

  applyLocal(P) {
    if (!this.local.size) return;
    const { mute, products, eff } = this.localRules();
    for (const [s, w] of eff) P[s] = w;
    for (const [s, drivers, lo, hi] of products) {
      if (!drivers.some((d) => eff.has(d))) continue;
      let w = 1;
      for (const d of drivers) w *= mute.has(d) ? 0 : (eff.has(d) ? eff.get(d) : P[d]);
      P[s] = Math.min(Math.max(w, lo), hi);
    }
  },

  disposeLocal() {
    clearTimeout(this.localTimer);
    this.localTimer = null;
    for (const [m, fn] of this.sliderModels || []) m.off("change:value", fn);
    this.sliderModels = [];
    this.model.off("change:_weight_slider_ids", this.onWeightSliders);
  },
};
