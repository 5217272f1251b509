// The geometry store of one widget model, shared by its views: what Python sent.
//
// Python -> front end (widgets/viewport/sync.py):
//   _faces      bytes, uint32 (m*3)   once per topology
//   _positions  bytes, float32 (n*3)  full buffer, when many vertices changed (or on load)
//   _labels     bytes, uint16 (n)     component index per vertex
//   msg:custom  {type: "patch", version[, seq]}, buffers [ids uint32 (k), values float32 (k*3)]
//               when fewer than ~1/3 of the vertices changed (seq: the gesture message it shows)
//   _tint  bytes, float32 (n) or empty: the surface tint (a tool's weights
//   msg:custom      {type: "tint_patch", version}, buffers [ids uint32, weights float32]
//                   weights, or a stroke handler's mask)
// GPU mode (_gpu_mode == "gpu", widgets/viewport/gpu.py): the rig once (_gpu_meta, _gpu_neutral,
// _gpu_morph_index, _gpu_morph_entries, _gpu_basis, _gpu_gain, _gpu_residual), then per update
//   msg:custom  {type: "gpu_params", version[, seq], count, k, hu}, buffers [params f32
//               (k weights, hu*3 shell offsets, 16 head matrix), residual ids u32, rows f32]
// in the same version sequence as patches; the views evaluate it (./gpu_morph.js) and read
// positions back when they need them on the CPU (picking, markers).
// Ordering: the widget manager decodes state updates asynchronously (a promise chain) but
// fires custom messages at once, so a message can arrive before the full update Python sent
// just before it. A message ahead of the version we have waits (held) until the full
// update brings us to the version before it; only a gap that lasts GAP_MS (a really
// missed update) asks Python for a full buffer: request_full / request_tint.
import { clipMethods } from "./gpu_clip.js";
import { cpuRowMethods } from "./gpu_cpu.js";
import { localWeightMethods } from "./gpu_local.js";
import { padded, texRows } from "./gpu_morph.js";
import { typed } from "./util.js";

const GAP_MS = 1000;
const TRACE_LEN = 24;

export class Store {
  constructor(model) {
    this.model = model;
    this.views = new Set();
    this.positions = null; // Float32Array n*3 (owned copy, patched in place)
    this.faces = null; // Uint32Array m*3
    this.labels = null; // Uint16Array n
    this.version = -1;
    this.topologyVersion = 0; // bumps when faces / vertex count change
    this.positionsVersion = 0; // bumps on every applied update
    this.lastPatchIds = null; // ids of the last sparse update (null = full)
    this.tintW = null; // Float32Array n: the tint weights (a tool's or a stroke handler's), or null
    this.tintVersion = -1;
    this.seq = 0; // gesture message numbers, unique over the views of this model
    this.gpu = null; // the rig for GPU evaluation (loadGpuRig), or null
    this.gpuParams = null; // Float32Array: weights, shell offsets, head matrix (+ page predictions)
    this.kernelParams = null; // the same as the kernel last sent them
    this.gpuMode = false; // Python sends parameters instead of vertex rows
    this.meta = {};
    this.held = []; // geometry messages ahead of our version: [content, buffers]
    this.gapTimer = null;
    this.trace = []; // the last TRACE_LEN updates seen (for the diagnosis a resync carries)
  }

  // Remember an update (kind, its version, what we did with it); a resync reports the list.
  note(kind, version, what = "") {
    this.trace.push([kind, version, what, Math.round(performance.now())]);
    if (this.trace.length > TRACE_LEN) this.trace.shift();
  }

  // The rig traits (on load and whenever _gpu_meta changes): only the parts whose version moved.
  loadGpuRig() {
    const m = this.model.get("_gpu_meta") || {};
    if (!m.n) return;
    let g = this.gpu;
    if (!g || g.n !== m.n) {
      g = { n: m.n, morphVersion: 0, baseVersion: 0, gainVersion: 0, basisVersion: 0, hu: 0, hq: 0, k: 0 };
      this.gpu = g;
      this.meta = {};
    }
    if (m.morph !== this.meta.morph) {
      g.k = m.k;
      g.half = !!m.half;
      g.index = padded(typed(this.model.get("_gpu_morph_index"), Uint32Array), 2);
      const raw = g.half
        ? typed(this.model.get("_gpu_morph_entries"), Uint16Array)
        : typed(this.model.get("_gpu_morph_entries"), Float32Array);
      g.entries = padded(raw, 4);
      g.entryRows = texRows(raw.length / 4);
      g.neutral = new Float32Array(typed(this.model.get("_gpu_neutral"), Float32Array));
      if (!g.residual || g.residual.length !== g.n * 3) g.residual = new Float32Array(g.n * 3);
      this.rebuildBase();
      g.morphVersion += 1;
    }
    if (m.gain !== this.meta.gain) {
      const gain = typed(this.model.get("_gpu_gain"), Float32Array);
      g.gain = padded(gain && gain.length === 2 * g.n ? gain : new Float32Array(2 * g.n).fill(1), 2);
      g.gainVersion += 1;
    }
    if (m.basis !== this.meta.basis) {
      g.hu = m.hu || 0;
      g.hq = Math.ceil(g.hu / 4);
      const b = typed(this.model.get("_gpu_basis"), Float32Array);
      g.basis = g.hq && b && b.length === g.n * g.hq * 4 ? padded(b, 4) : null;
      if (!g.basis) { g.hu = 0; g.hq = 0; }
      g.basisRows = texRows(g.n * g.hq);
      g.basisVersion += 1;
    }
    if (m.morph !== this.meta.morph || m.gain !== this.meta.gain || m.basis !== this.meta.basis) {
      this.note("rig", this.version, `morph ${m.morph} gain ${m.gain} basis ${m.basis}`);
    }
    this.meta = { ...m };
  }

  // base = neutral + residual, RGBA texels (all rows, or only `ids`)
  rebuildBase(ids) {
    const g = this.gpu;
    if (!g || !g.neutral) return;
    if (!g.base || g.base.length < g.n * 4) g.base = padded(new Float32Array(g.n * 4), 4);
    const B = g.base, N = g.neutral, R = g.residual;
    const one = (i) => {
      B[4 * i] = N[3 * i] + R[3 * i];
      B[4 * i + 1] = N[3 * i + 1] + R[3 * i + 1];
      B[4 * i + 2] = N[3 * i + 2] + R[3 * i + 2];
    };
    if (ids) for (let k = 0; k < ids.length; k++) { if (ids[k] < g.n) one(ids[k]); }
    else for (let i = 0; i < g.n; i++) one(i);
    g.baseVersion += 1;
  }

  // The GPU state of a full update (traits): mode, parameters, the whole residual.
  loadGpuFull() {
    this.gpuMode = this.model.get("_gpu_mode") === "gpu";
    if (!this.gpuMode) return;
    this.loadGpuRig();
    const g = this.gpu;
    const P = typed(this.model.get("_gpu_params"), Float32Array);
    this.kernelParams = P ? new Float32Array(P) : null; // the kernel's own, before predictions
    this.gpuParams = P ? new Float32Array(P) : null;
    this.reconcileLocal();
    const R = typed(this.model.get("_gpu_residual"), Float32Array);
    if (g && R && R.length === g.n * 3) {
      g.residual = new Float32Array(R);
      this.rebuildBase();
    }
  }

  // Is the GPU state complete and consistent with the positions / faces we have?
  gpuReady() {
    return !this.gpuMissing();
  }

  // What the GPU path lacks ("" when ready): the test hook's diagnosis (fwbGpuState).
  gpuMissing() {
    const g = this.gpu;
    if (!this.gpuMode) return "mode";
    if (!g) return "rig";
    if (!g.index || !g.base || !g.gain) return "rig textures";
    if (!this.gpuParams) return "parameters";
    if (!this.positions || this.positions.length !== g.n * 3) return "vertex count";
    if (this.gpuParams.length < g.k + 3 * g.hu + 16) return "parameter count";
    return "";
  }

  applyGpuParams(content, buffers) {
    if (content.version <= this.version) {
      this.note("params", content.version, "stale");
      return;
    }
    if (content.version !== this.version + 1 || !this.gpu || !this.positions) {
      this.note("params", content.version, `held at ${this.version}${this.gpu ? "" : ", no rig"}`);
      this.hold(content, buffers);
      return;
    }
    this.note("params", content.version, "applied");
    this.gpuMode = true;
    this.kernelParams = new Float32Array(typed(buffers[0], Float32Array));
    this.gpuParams = new Float32Array(this.kernelParams);
    this.reconcileLocal(); // sliders the kernel has not answered yet stay as the page has them
    const ids = typed(buffers[1], Uint32Array);
    const rows = typed(buffers[2], Float32Array);
    const g = this.gpu;
    if (ids && ids.length && rows && rows.length === ids.length * 3) {
      const R = g.residual;
      for (let k = 0; k < ids.length; k++) {
        const i = ids[k];
        if (i >= g.n) continue;
        R[3 * i] = rows[3 * k]; R[3 * i + 1] = rows[3 * k + 1]; R[3 * i + 2] = rows[3 * k + 2];
      }
      this.rebuildBase(ids);
    }
    this.version = content.version;
    this.lastPatchIds = null;
    this.lastUpdateTime = performance.now();
    this.positionsVersion += 1;
    this.notify();
  }

  nextSeq() {
    this.seq += 1;
    return this.seq;
  }

  loadTintFull() {
    const version = this.model.get("_tint_version");
    if (version === this.tintVersion) return;
    const w = typed(this.model.get("_tint"), Float32Array);
    this.tintW = w && w.length ? new Float32Array(w) : null;
    this.tintVersion = version;
    for (const v of this.views) v.tintChanged(null);
  }

  applyTintPatch(content, buffers) {
    if (content.version <= this.tintVersion) return;
    const n = this.positions ? this.positions.length / 3 : 0;
    if (content.version !== this.tintVersion + 1 || (!this.tintW && n === 0)) {
      this.model.send({ type: "request_tint", have: this.tintVersion });
      return;
    }
    if (!this.tintW) this.tintW = new Float32Array(n);
    const ids = typed(buffers[0], Uint32Array);
    const values = typed(buffers[1], Float32Array);
    const W = this.tintW;
    for (let k = 0; k < ids.length; k++) if (ids[k] < W.length) W[ids[k]] = values[k];
    this.tintVersion = content.version;
    for (const v of this.views) v.tintChanged(ids);
  }

  loadFull() {
    const pos = typed(this.model.get("_positions"), Float32Array);
    const faces = typed(this.model.get("_faces"), Uint32Array);
    const labels = typed(this.model.get("_labels"), Uint16Array);
    if (!pos || !faces) return;
    const version = this.model.get("_version");
    // Every full update bumps _version; change events for several traits of one
    // message call this repeatedly, the first call does the work.
    if (version === this.version && this.model.get("_topology") === this._topology) return;
    this.note("full", version, `from ${this.version}, mode ${this.model.get("_gpu_mode")}`);
    const topo =
      !this.positions ||
      this.positions.length !== pos.length ||
      !this.faces ||
      this.faces.length !== faces.length ||
      this.model.get("_topology") !== this._topology;
    // Own copies: the DataView may alias a buffer that the widget manager reuses.
    this.positions = new Float32Array(pos);
    if (topo) {
      this.faces = new Uint32Array(faces);
      this.labels = labels && labels.length * 3 === pos.length ? new Uint16Array(labels) : null;
      this._topology = this.model.get("_topology");
      this.topologyVersion += 1;
    }
    this.version = version;
    this.lastPatchIds = null;
    this.lastUpdateTime = performance.now();
    this.positionsVersion += 1;
    this.loadGpuFull();
    this.notify();
    this.replayHeld();
  }

  // Python changes _gpu_params only in GPU mode, after the rig: a page that sees it change
  // without either missed the update that switched it (seen once in ~20 runs of a browser
  // test: the model showed the later update but not the switch). Ask for all of it, once
  // per version.
  gpuParamsTraitChanged() {
    const m = this.model;
    if (m.get("_gpu_mode") === "gpu" && (m.get("_gpu_meta") || {}).n) return;
    if (this.rigAsked === m.get("_version")) return;
    this.rigAsked = m.get("_version");
    this.requestFull("rig", true);
  }

  // A geometry message (gpu_params / patch) ahead of our version: keep it for the full
  // update it overtook; ask Python for a full buffer if none comes.
  hold(content, buffers) {
    this.held.push([content, buffers]);
    if (!this.gapTimer) {
      this.gapTimer = setTimeout(() => {
        this.gapTimer = null;
        if (!this.held.length) return;
        this.requestFull("gap", !this.gpu);
        this.held = [];
      }, GAP_MS);
    }
  }

  // Ask Python for everything (a protocol step for a real gap, counted: the browser tests read
  // globalThis.fwbResyncs and require none).
  requestFull(why, rig) {
    const g = globalThis;
    const m = this.model;
    const record = {
      why, have: this.version, at: Math.round(performance.now()),
      // what the widget model holds (a full update whose change events never reached us shows
      // here as a newer _version than ours) and the updates we saw last
      model: { version: m.get("_version"), mode: m.get("_gpu_mode"), meta: { ...(m.get("_gpu_meta") || {}) } },
      held: this.held.map(([c]) => [c.type, c.version]),
      trace: this.trace.slice(),
    };
    delete record.model.meta.names; // a copy: the model's own _gpu_meta keeps them
    delete record.model.meta.columns;
    (g.fwbResyncs = g.fwbResyncs || []).push(record);
    m.send({ type: "request_full", have: this.version, rig, why });
  }

  // Apply the held messages that follow our version now (in order), drop older ones.
  replayHeld() {
    if (!this.held.length) return;
    const held = this.held.sort((a, b) => a[0].version - b[0].version);
    this.held = [];
    for (const [content, buffers] of held) {
      if (content.version <= this.version) continue;
      if (content.type === "gpu_params") this.applyGpuParams(content, buffers);
      else this.applyPatch(content, buffers); // a later gap holds it again
    }
    if (!this.held.length) { clearTimeout(this.gapTimer); this.gapTimer = null; }
  }

  applyPatch(content, buffers) {
    if (content.version <= this.version) { // stale (already in a newer full state)
      this.note("patch", content.version, "stale");
      return;
    }
    if (content.version !== this.version + 1 || !this.positions) {
      this.note("patch", content.version, `held at ${this.version}`);
      this.hold(content, buffers); // a full update still being decoded, or a missed one
      return;
    }
    this.note("patch", content.version, "applied");
    const ids = typed(buffers[0], Uint32Array);
    const values = typed(buffers[1], Float32Array);
    const P = this.positions;
    const n = P.length / 3;
    for (let k = 0; k < ids.length; k++) {
      const i = ids[k];
      if (i >= n) continue;
      P[3 * i] = values[3 * k];
      P[3 * i + 1] = values[3 * k + 1];
      P[3 * i + 2] = values[3 * k + 2];
    }
    this.gpuMode = false;
    this.version = content.version;
    this.lastPatchIds = ids;
    this.lastUpdateTime = performance.now();
    this.positionsVersion += 1;
    this.notify();
  }

  notify() {
    for (const v of this.views) v.geometryChanged();
  }
}

Object.assign(Store.prototype, clipMethods, cpuRowMethods, localWeightMethods);
