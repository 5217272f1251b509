// The geometry store of one widget model, shared by its views: what Python sent.
//
// Python -> front end (widgets/viewport/sync.py):
//   _faces      bytes, uint32 (m*3)   once per topology
//   _positions  bytes, float32 (n*3)  full buffer, when many vertices changed (or on load)
//   _labels     bytes, uint16 (n)     component index per vertex
//   msg:custom  {type: "patch", version[, seq]}, buffers [ids uint32 (k), values float32 (k*3)]
//               when fewer than ~1/3 of the vertices changed (seq: the gesture message it shows)
//   _paint_weights  bytes, float32 (n) or empty: the paint overlay (selected expression's
//   msg:custom      {type: "paint_patch", version}, buffers [ids uint32, weights float32]
//                   weights, or a stroke handler's mask)
// A version gap (a missed update) asks Python for a full buffer: request_full / request_paint.
import { typed } from "./util.js";

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
    this.paintW = null; // Float32Array n: painted weights of the selected expression, or null
    this.paintVersion = -1;
    this.seq = 0; // gesture message numbers, unique over the views of this model
  }

  nextSeq() {
    this.seq += 1;
    return this.seq;
  }

  loadPaintFull() {
    const version = this.model.get("_paint_version");
    if (version === this.paintVersion) return;
    const w = typed(this.model.get("_paint_weights"), Float32Array);
    this.paintW = w && w.length ? new Float32Array(w) : null;
    this.paintVersion = version;
    for (const v of this.views) v.paintChanged(null);
  }

  applyPaintPatch(content, buffers) {
    if (content.version <= this.paintVersion) return;
    const n = this.positions ? this.positions.length / 3 : 0;
    if (content.version !== this.paintVersion + 1 || (!this.paintW && n === 0)) {
      this.model.send({ type: "request_paint", have: this.paintVersion });
      return;
    }
    if (!this.paintW) this.paintW = new Float32Array(n);
    const ids = typed(buffers[0], Uint32Array);
    const values = typed(buffers[1], Float32Array);
    const W = this.paintW;
    for (let k = 0; k < ids.length; k++) if (ids[k] < W.length) W[ids[k]] = values[k];
    this.paintVersion = content.version;
    for (const v of this.views) v.paintChanged(ids);
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
    this.notify();
  }

  applyPatch(content, buffers) {
    if (!this.positions) return;
    if (content.version <= this.version) return; // stale (already in a newer full state)
    if (content.version !== this.version + 1) {
      // A gap means we missed an update (e.g. reload race): ask Python for a full buffer.
      // This is the only kernel message the viewport ever sends, and only on error.
      this.model.send({ type: "request_full", have: this.version });
      return;
    }
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
