// Fast interaction (like Maya's): while the rig's parameters change — a slider moves, a
// handle is dragged, a clip plays — a view whose full frame is slow draws a simplified copy
// of the face, evaluated on the GPU for its own vertices only, and draws the full mesh once
// the changes pause (SETTLE_MS). Methods mixed into View (./scene.js), GPU path only.
//
// "Slow" is measured, not guessed: once per mesh and canvas size the view times one full
// evaluation + draw to the last pixel (calibrate; 120-150 ms at 80k vertices on
// SwiftShader, whose draw costs ~0.55 µs per triangle plus the shading of the pixels). A
// slow view drafts with DRAFT_TRIANGLES triangles shaded by a Lambert material (cheaper per
// pixel). Hardware GPUs draw the full mesh in a few ms and never see a draft
// (fast_interaction "auto").
//
// The draft keeps a subset of the mesh's own vertices (meshoptimizer's simplifier collapses
// edges onto existing vertices), so the GPU evaluates exactly the rig's values there; only
// the triangles between them are coarser. Written here, not taken from a library: three.js
// has no level-of-detail for morphs evaluated into textures.
//
// Python side: Viewport.fast_interaction ("auto" | "on" | "off", widgets/viewport/widget.py).
// Test hooks: data-detail ("draft" | "full") of the last frame, data-draft-frame /
// data-draft-frame-time (the draft frames; data-frame counts full-detail frames only),
// data-full-frame-ms (the calibration), data-draft-triangles.
import * as THREE from "three";
import { MeshoptSimplifier } from "meshoptimizer/simplifier";
import { patchMaterial } from "./gpu_morph.js";

const SETTLE_MS = 140; // no new parameters for this long: draw the full mesh
const SLOW_MS = 30; // a full frame slower than this is "slow" (auto)
// The draft's size: on SwiftShader (2 cores, 320 x 520 px) 8k triangles draw in ~16 ms with
// the draft's material, its evaluation ~5 ms at 80k or 318k vertices; a face of 8k
// triangles is still finer than ARKit's face mesh (2.3k).
const DRAFT_TRIANGLES = 8000;

// Simplify `faces` (triangles over `positions`, n*3) to about `target` triangles.
// Returns { ids (m) the kept vertices, faces (in 0..m-1) } or null when it does not shrink.
export function simplifyFaces(faces, positions, target) {
  if (!MeshoptSimplifier.supported || faces.length / 3 <= target) return null;
  const [idx] = MeshoptSimplifier.simplify(
    new Uint32Array(faces), positions, 3, 3 * target, 0.05, ["Prune"],
  );
  if (idx.length >= faces.length || idx.length < 3) return null;
  // kept vertices in ascending order: texel t of the draft reads the rig's texels near
  // those of t - 1 (a cache-friendly walk through the rig's textures)
  const n = positions.length / 3;
  const used = new Uint8Array(n);
  for (let i = 0; i < idx.length; i++) used[idx[i]] = 1;
  const remap = new Int32Array(n);
  const ids = [];
  for (let v = 0; v < n; v++) if (used[v]) { remap[v] = ids.length; ids.push(v); }
  const out = new Uint32Array(idx.length);
  for (let i = 0; i < idx.length; i++) out[i] = remap[idx[i]];
  return { ids: Uint32Array.from(ids), faces: out };
}

// Do `faces` (over positions P, m*3) wind outward? The signed volume they enclose about
// their centroid is positive (an open face mesh too: its neck or mouth opening is small).
export function outward(faces, P) {
  const m = P.length / 3;
  let cx = 0, cy = 0, cz = 0;
  for (let i = 0; i < m; i++) { cx += P[3 * i]; cy += P[3 * i + 1]; cz += P[3 * i + 2]; }
  cx /= m; cy /= m; cz /= m;
  let vol = 0;
  for (let f = 0; f < faces.length; f += 3) {
    const a = 3 * faces[f], b = 3 * faces[f + 1], c = 3 * faces[f + 2];
    const ax = P[a] - cx, ay = P[a + 1] - cy, az = P[a + 2] - cz;
    const bx = P[b] - cx, by = P[b + 1] - cy, bz = P[b + 2] - cz;
    const qx = P[c] - cx, qy = P[c + 1] - cy, qz = P[c + 2] - cz;
    vol += ax * (by * qz - bz * qy) + ay * (bz * qx - bx * qz) + az * (bx * qy - by * qx);
  }
  return vol > 0;
}

export const draftViewMethods = {
  initDraft() {
    this.fullFrameMs = null; // the calibration of (calKey)
    this.calKey = "";
    this.draftMeshKey = "";
    this.draftNone = false; // simplifying did not shrink the mesh
    this.draftBuilding = false;
    this.draftMesh = null;
    this.lastDetail = "full";
    this.draftFrames = 0;
    this.settleTimer = null;
    this.fullStale = false; // the full targets are older than the parameters
    this.onFastTrait = () => { this.fullFrameMs = null; this.calKey = ""; };
    this.model.on("change:fast_interaction", this.onFastTrait);
  },

  // Draw this update as a draft? (also starts the draft's build once the view is slow)
  draftWanted() {
    const mode = this.model.get("fast_interaction") || "auto";
    if (mode === "off" || !this.gpu || this.forceFull) return false;
    // the draft follows the drawn triangles; the calibration also the canvas size (a
    // playing clip lowers the pixel ratio: re-timed, not re-simplified)
    const meshKey = `${this.store.topologyVersion}:${this.indexVersion || 0}`;
    if (meshKey !== this.draftMeshKey) {
      this.draftMeshKey = meshKey;
      this.draftNone = false;
      this.dropDraftMesh();
    }
    const el = this.renderer.domElement;
    const calKey = `${meshKey}:${el.width}x${el.height}`;
    if (calKey !== this.calKey) {
      this.calKey = calKey;
      this.fullFrameMs = null;
    }
    if (mode === "auto" && !(this.fullFrameMs > SLOW_MS)) return false; // not slow, or not timed yet
    if (this.draftNone) return false;
    if (!this.draftMesh) { this.buildDraft(); return false; }
    return true;
  },

  // After a full GPU frame: time one full evaluation + draw to the last pixel, once per key.
  calibrate() {
    if (this.fullFrameMs !== null || (this.model.get("fast_interaction") || "auto") !== "auto") return;
    const gl = this.renderer.getContext();
    const px = new Uint8Array(4);
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px); // drain what is queued
    const t0 = performance.now();
    this.gpu.evaluate();
    this.renderer.render(this.scene, this.camera);
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    this.fullFrameMs = performance.now() - t0;
    this.el.setAttribute("data-full-frame-ms", this.fullFrameMs.toFixed(1));
    if (this.fullFrameMs > SLOW_MS && !this.draftMesh && !this.draftNone) this.buildDraft(); // ready for the first change
  },

  // Simplify the drawn triangles (off the main path: meshoptimizer's WASM loads async).
  buildDraft() {
    if (this.draftBuilding || !this.geometry.index || !this.store.gpu) return;
    this.draftBuilding = true;
    const key = this.draftMeshKey;
    MeshoptSimplifier.ready.then(() => {
      this.draftBuilding = false;
      if (key !== this.draftMeshKey || !this.gpu || !this.store.gpu || this.draftMesh) return;
      const d = simplifyFaces(this.geometry.index.array, this.store.gpu.neutral, DRAFT_TRIANGLES);
      if (!d) { this.draftNone = true; return; } // nothing to gain
      this.gpu.setDraft(d.ids, d.faces);
      const geo = new THREE.BufferGeometry();
      const m = d.ids.length;
      const P = new Float32Array(m * 3); // for three.js's bounds only: the GPU draws positions
      const N = this.store.gpu.neutral;
      for (let i = 0; i < m; i++) for (let c = 0; c < 3; c++) P[3 * i + c] = N[3 * d.ids[i] + c];
      geo.setAttribute("position", new THREE.BufferAttribute(P, 3));
      geo.setAttribute("normal", new THREE.BufferAttribute(new Float32Array(m * 3), 3));
      geo.setAttribute("color", new THREE.BufferAttribute(new Float32Array(m * 3), 3));
      geo.setIndex(new THREE.BufferAttribute(d.faces, 1));
      // Lambert: on SwiftShader the draft's draw is mostly per-pixel shading, and Lambert
      // costs ~0.4x the face's standard (PBR) material at the same size (13 vs 35 ms at
      // 320 x 520 px, double-sided); the full mesh keeps the standard one. Back faces are
      // culled when the triangles wind outward (another ~25 %): a draft may lose the back
      // of a single-sided part (a lash card) that the full mesh shows
      const side = outward(d.faces, P) ? THREE.FrontSide : THREE.DoubleSide;
      const mat = new THREE.MeshLambertMaterial({ vertexColors: true, side });
      patchMaterial(mat, this.gpu.draftUniforms);
      this.draftMesh = new THREE.Mesh(geo, mat);
      this.draftMesh.frustumCulled = false;
      this.draftMesh.visible = false;
      this.draftIds = d.ids;
      this.draftColorVersion = -1;
      this.scene.add(this.draftMesh);
      this.el.setAttribute("data-draft-triangles", String(d.faces.length / 3));
    });
  },

  dropDraftMesh() {
    if (this.draftMesh) {
      this.scene.remove(this.draftMesh);
      this.draftMesh.geometry.dispose();
      this.draftMesh.material.dispose();
      this.draftMesh = null;
    }
    if (this.gpu) this.gpu.dropDraft();
    this.el.removeAttribute("data-draft-triangles");
  },

  // Evaluate and show the draft for the current parameters; the full mesh follows on settle.
  drawDraft() {
    this.gpu.evaluateDraft();
    const src = this.geometry.getAttribute("color");
    if (src && src.version !== this.draftColorVersion) {
      const dst = this.draftMesh.geometry.getAttribute("color");
      const ids = this.draftIds;
      for (let i = 0; i < ids.length; i++) {
        for (let c = 0; c < 3; c++) dst.array[3 * i + c] = src.array[3 * ids[i] + c];
      }
      dst.needsUpdate = true;
      this.draftColorVersion = src.version;
    }
    this.showDetail("draft");
    this.fullStale = true;
    this.draftFrames += 1;
    clearTimeout(this.settleTimer);
    this.settleTimer = setTimeout(() => this.settle(), SETTLE_MS);
  },

  // The changes paused: draw the full mesh (unless a clip still plays: it drafts on).
  settle() {
    this.settleTimer = null;
    if (this.lastDetail !== "draft") return;
    if (this.store.clipPlay) { this.settleTimer = setTimeout(() => this.settle(), SETTLE_MS); return; }
    this.forceFull = true;
    this.geometryDirty = true;
    this.requestRender();
  },

  // Show the draft or the full mesh (its wireframe overlay only with the full mesh: the
  // overlay draws the full mesh's triangles).
  showDetail(detail) {
    const draft = detail === "draft";
    if (this.draftMesh) this.draftMesh.visible = draft;
    this.mesh.visible = !draft;
    this.wire.visible = !draft && !!this.model.get("wireframe");
    this.lastDetail = detail;
    this.el.setAttribute("data-detail", detail);
  },

  // The full targets are current (before reading positions back).
  ensureFullEvaluated() {
    if (this.fullStale && this.gpu) {
      this.gpu.evaluate();
      this.fullStale = false;
    }
  },

  disposeDraft() {
    clearTimeout(this.settleTimer);
    this.model.off("change:fast_interaction", this.onFastTrait);
    this.dropDraftMesh();
  },
};
