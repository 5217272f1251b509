// Feature-graph overlay (Bickel et al. 2008 §5.1), Python -> front end:
//   _feature_edges   bytes, uint32 (F*2): vertex ids of the edges (between handles)
//   _feature_strain  bytes, float32 (F): relative stretch of each edge
//   feature_graph (bool, draw it), strain_range (|strain| drawn in full colour)
// Fat line segments over the surface, blue (compressed) - grey (rest) - red (stretched),
// end points following the drawn geometry; a colour-scale legend in the corner.
// Self-contained: a View gets one in render() and calls beforeRender() once per render.
import * as THREE from "three";
import { LineSegments2 } from "three/examples/jsm/lines/LineSegments2.js";
import { LineSegmentsGeometry } from "three/examples/jsm/lines/LineSegmentsGeometry.js";
import { LineMaterial } from "three/examples/jsm/lines/LineMaterial.js";
import { srgbToLinear, typed } from "./util.js";

const STRAIN_REST = [0.72, 0.72, 0.72]; // sRGB grey: edge at its rest length
const STRAIN_STRETCH = [0.93, 0.16, 0.12]; // red: longer than at rest
const STRAIN_COMPRESS = [0.16, 0.42, 1.0]; // blue: shorter than at rest
const FEATURE_LINE_PX = 3; // line width in CSS pixels
// Depth bias of the lines. An edge is a straight chord between two handles on the
// curved skin and dips under it: by a few % of its length over the cheeks, by up to
// about half of it where it passes under the lips or the side of the nose (measured
// on the sample head). Each end point is moved toward the camera ALONG ITS VIEW RAY
// (it projects to the same pixel, only its depth changes) by FEATURE_DEPTH_PULL times
// its edge's length (more than the dip: seen at an angle, the skin in front of a chord
// is deeper than along the normal). The lines are then whole over the face seen from
// the front, while from behind the head (about ten edge lengths deep) hides them. A
// tighter, per-edge bias (the dip measured in Python) hid the edges under the lips
// from the front, and a ray-cast depth was slow and no tighter (eyelashes, nose).
const FEATURE_DEPTH_PULL = 1.5;

// sRGB colour of a relative stretch s, full colour at |s| >= range.
function strainColor(s, range) {
  const t = Math.max(-1, Math.min(1, s / (range > 0 ? range : 0.2)));
  const end = t >= 0 ? STRAIN_STRETCH : STRAIN_COMPRESS;
  const a = Math.abs(t);
  return STRAIN_REST.map((c, i) => c + a * (end[i] - c));
}

export class FeatureGraphOverlay {
  constructor(view, model) {
    this.view = view;
    this.model = model;
    this.edges = new Uint32Array(0);
    this.strain = new Float32Array(0);
    this.ends = new Float32Array(0); // (F*6) edge end points on the drawn geometry
    this.edgesDirty = true;
    this.colorsDirty = true;
    this.seenPositions = -1;
    this.line = null;
    if (!view.renderer) return; // no WebGL: the view shows its error text
    this.geometry = new LineSegmentsGeometry();
    this.material = new LineMaterial({
      vertexColors: true,
      linewidth: FEATURE_LINE_PX,
      worldUnits: false,
      // Depth-tested against the face (drawn after it, renderOrder 0.5), so the head
      // hides the lines seen from behind; the end points are pulled toward the camera
      // (FEATURE_DEPTH_PULL) because the chords between handles dip under the skin.
      // Not written to the depth buffer: the handle markers (renderOrder 1) stay whole.
      depthTest: true,
      depthWrite: false,
      transparent: false,
    });
    this.line = new LineSegments2(this.geometry, this.material);
    this.line.frustumCulled = false;
    this.line.renderOrder = 0.5;
    this.line.visible = false;
    view.scene.add(this.line);
    this.legend = this.buildLegend();
    view.el.appendChild(this.legend);
    this.handlers = {
      "change:_feature_edges": () => { this.loadEdges(); view.requestRender(); },
      "change:_feature_strain": () => { this.loadStrain(); view.requestRender(); },
      "change:feature_graph": () => view.requestRender(),
      "change:strain_range": () => { this.colorsDirty = true; this.updateLegend(); view.requestRender(); },
    };
    for (const [ev, fn] of Object.entries(this.handlers)) model.on(ev, fn);
    // Test hook: what is drawn, {count, visible, strain: [...], colors: [[r, g, b] sRGB]}.
    view.el.fwbFeatureGraph = () => this.describe();
    this.loadEdges();
    this.loadStrain();
  }

  buildLegend() {
    const box = document.createElement("div");
    box.className = "fwb-strain-legend";
    Object.assign(box.style, {
      position: "absolute", right: "8px", top: "8px", padding: "4px 6px",
      background: "rgba(20,22,26,0.72)", color: "#eee", font: "11px sans-serif",
      borderRadius: "3px", pointerEvents: "none", display: "none",
    });
    const title = document.createElement("div");
    title.textContent = "feature-graph strain";
    const bar = document.createElement("div");
    const css = (c) => `rgb(${c.map((x) => Math.round(255 * x)).join(",")})`;
    Object.assign(bar.style, {
      width: "150px", height: "8px", margin: "3px 0",
      background: `linear-gradient(to right, ${css(STRAIN_COMPRESS)}, ${css(STRAIN_REST)}, ${css(STRAIN_STRETCH)})`,
    });
    const labels = document.createElement("div");
    Object.assign(labels.style, { display: "flex", justifyContent: "space-between", width: "150px" });
    this.legendLabels = [0, 1, 2].map(() => labels.appendChild(document.createElement("span")));
    box.append(title, bar, labels);
    this.updateLegendLabels = () => {
      const r = Number(this.model.get("strain_range")) || 0.2;
      const pct = Math.round(100 * r);
      this.legendLabels[0].textContent = `\u2212${pct}% compressed`;
      this.legendLabels[1].textContent = "rest";
      this.legendLabels[2].textContent = `+${pct}% stretched`;
    };
    this.updateLegendLabels();
    return box;
  }

  updateLegend() {
    if (this.updateLegendLabels) this.updateLegendLabels();
  }

  loadEdges() {
    const e = typed(this.model.get("_feature_edges"), Uint32Array);
    this.edges = e && e.length ? new Uint32Array(e) : new Uint32Array(0);
    this.edgesDirty = true;
    this.colorsDirty = true;
    this.view.el.setAttribute("data-feature-edges", String(this.edges.length / 2));
  }

  loadStrain() {
    const f = typed(this.model.get("_feature_strain"), Float32Array);
    this.strain = f && f.length ? new Float32Array(f) : new Float32Array(0);
    this.colorsDirty = true;
  }

  visible() {
    return !!this.model.get("feature_graph") && this.edges.length > 0 && !!this.view.store.positions;
  }

  // Called by View.renderNow before each render: end points from the drawn geometry,
  // colours from the strain, line width in pixels of the current canvas size.
  beforeRender() {
    if (!this.line) return;
    const show = this.visible();
    this.line.visible = show;
    this.legend.style.display = show ? "block" : "none";
    this.view.el.setAttribute("data-feature-visible", show ? "1" : "0");
    if (!show) return;
    const s = this.view.store;
    const F = this.edges.length / 2;
    if (this.edgesDirty || this.seenPositions !== s.positionsVersion) {
      if (this.edgesDirty && this.view.cpuRows) this.view.cpuRows(this.edges); // GPU path
      const P = s.positions;
      const n = P.length / 3;
      if (this.ends.length !== F * 6) this.ends = new Float32Array(F * 6);
      const X = this.ends;
      const E = this.edges;
      for (let k = 0; k < E.length; k++) {
        const i = Math.min(E[k], n - 1);
        X[3 * k] = P[3 * i]; X[3 * k + 1] = P[3 * i + 1]; X[3 * k + 2] = P[3 * i + 2];
      }
      this.seenPositions = s.positionsVersion;
    }
    // Every render (the camera may have moved): the end points pulled toward the camera.
    const attr = this.geometry.getAttribute("instanceStart");
    const reuse = !this.edgesDirty && attr && attr.data.array.length === F * 6;
    const buf = reuse ? attr.data.array : new Float32Array(F * 6);
    this.pullTowardCamera(this.ends, buf);
    if (reuse) attr.data.needsUpdate = true;
    else this.geometry.setPositions(buf);
    if (!reuse) this.colorsDirty = true; // new instance buffers need their colours
    this.edgesDirty = false;
    if (this.colorsDirty) {
      const range = Number(this.model.get("strain_range")) || 0.2;
      const C = new Float32Array(F * 6);
      let maxAbs = 0;
      for (let k = 0; k < F; k++) {
        const v = k < this.strain.length ? this.strain[k] : 0;
        maxAbs = Math.max(maxAbs, Math.abs(v));
        const rgb = strainColor(v, range).map(srgbToLinear);
        C.set(rgb, 6 * k);
        C.set(rgb, 6 * k + 3);
      }
      this.geometry.setColors(C);
      this.colorsDirty = false;
      this.view.el.setAttribute("data-feature-strain-max", maxAbs.toFixed(4));
    }
    const size = this.view.renderer.getSize(new THREE.Vector2());
    this.material.resolution.set(size.x, size.y);
  }

  // out = the end points X (F*6) moved toward the camera along their view rays by
  // FEATURE_DEPTH_PULL x their edge's length (never past the near plane).
  pullTowardCamera(X, out) {
    const c = this.view.camera.position;
    const near = this.view.camera.near;
    for (let k = 0; k < X.length; k += 6) {
      const len = Math.hypot(X[k + 3] - X[k], X[k + 4] - X[k + 1], X[k + 5] - X[k + 2]);
      const pull = FEATURE_DEPTH_PULL * len;
      for (let j = k; j < k + 6; j += 3) {
        const dx = X[j] - c.x, dy = X[j + 1] - c.y, dz = X[j + 2] - c.z;
        const dist = Math.hypot(dx, dy, dz);
        const f = dist > 0 ? Math.max(dist - pull, Math.min(dist, 2 * near)) / dist : 1;
        out[j] = c.x + f * dx; out[j + 1] = c.y + f * dy; out[j + 2] = c.z + f * dz;
      }
    }
  }

  describe() {
    const range = Number(this.model.get("strain_range")) || 0.2;
    const F = this.edges.length / 2;
    const strain = Array.from({ length: F }, (_, k) => (k < this.strain.length ? this.strain[k] : 0));
    return {
      count: F,
      visible: !!(this.line && this.line.visible),
      strain,
      colors: strain.map((v) => strainColor(v, range)),
    };
  }

  dispose() {
    if (this.handlers) for (const [ev, fn] of Object.entries(this.handlers)) this.model.off(ev, fn);
    if (this.line) {
      this.view.scene.remove(this.line);
      this.geometry.dispose();
      this.material.dispose();
    }
    if (this.legend) this.legend.remove();
    delete this.view.el.fwbFeatureGraph;
    this.view.featureGraph = null;
  }
}
