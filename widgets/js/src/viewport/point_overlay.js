// Free 3-D points drawn over the face: the capture tab's input markers, landmarks or a
// point cloud at the current frame (they are not mesh vertices, so not handle markers).
//   _overlay_points  bytes, float32 (p*3)  positions in model space (finite only)
//   _overlay_colors  bytes, uint8 (p*3)    sRGB per point (may be empty: one colour)
//   overlay_point_px float                 point size in CSS pixels
// Drawn as screen-sized round points, always on top (depthTest off), so a marker behind
// the lips or inside a cloud stays visible. Test hook: data-overlay-points = count drawn
// at the last render, el.fwbOverlayProject() = their page coordinates.
import * as THREE from "three";
import { typed } from "./util.js";

const DEFAULT_COLOR = new THREE.Color(0x33ff99);

export class PointOverlay {
  constructor(view, model) {
    this.view = view;
    this.model = model;
    this.points = null;
    if (!view.renderer) return;
    this.geometry = new THREE.BufferGeometry();
    this.material = new THREE.PointsMaterial({
      size: 6, sizeAttenuation: false, vertexColors: true, depthTest: false, transparent: true,
    });
    this.points = new THREE.Points(this.geometry, this.material);
    this.points.frustumCulled = false;
    this.points.renderOrder = 2;
    view.scene.add(this.points);
    this.handlers = {
      "change:_overlay_points": () => { this.load(); view.requestRender(); },
      "change:_overlay_colors": () => { this.load(); view.requestRender(); },
      "change:overlay_point_px": () => { this.material.size = this.pixelSize(); view.requestRender(); },
    };
    for (const [ev, fn] of Object.entries(this.handlers)) model.on(ev, fn);
    view.el.fwbOverlayProject = () => this.project();
    this.load();
  }

  pixelSize() {
    const px = Number(this.model.get("overlay_point_px")) || 6;
    return px * (window.devicePixelRatio || 1);
  }

  load() {
    const P = typed(this.model.get("_overlay_points"), Float32Array) || new Float32Array(0);
    const n = Math.floor(P.length / 3);
    const C8 = typed(this.model.get("_overlay_colors"), Uint8Array);
    const C = new Float32Array(n * 3);
    const c = new THREE.Color();
    for (let i = 0; i < n; i++) {
      if (C8 && C8.length === n * 3) c.setRGB(C8[3 * i] / 255, C8[3 * i + 1] / 255, C8[3 * i + 2] / 255, THREE.SRGBColorSpace);
      else c.copy(DEFAULT_COLOR);
      C[3 * i] = c.r; C[3 * i + 1] = c.g; C[3 * i + 2] = c.b;
    }
    this.geometry.setAttribute("position", new THREE.BufferAttribute(P.slice(0, n * 3), 3));
    this.geometry.setAttribute("color", new THREE.BufferAttribute(C, 3));
    this.geometry.setDrawRange(0, n);
    this.material.size = this.pixelSize();
    this.points.visible = n > 0;
    this.view.el.setAttribute("data-overlay-points", String(n));
  }

  project() {
    const attr = this.geometry ? this.geometry.getAttribute("position") : null;
    if (!attr || !this.view.renderer) return [];
    const rect = this.view.renderer.domElement.getBoundingClientRect();
    const v = new THREE.Vector3();
    const out = [];
    for (let i = 0; i < attr.count; i++) {
      v.fromBufferAttribute(attr, i).project(this.view.camera);
      out.push([rect.left + ((v.x + 1) / 2) * rect.width, rect.top + ((1 - v.y) / 2) * rect.height]);
    }
    return out;
  }

  dispose() {
    if (this.handlers) for (const [ev, fn] of Object.entries(this.handlers)) this.model.off(ev, fn);
    if (this.points) {
      this.view.scene.remove(this.points);
      this.geometry.dispose();
      this.material.dispose();
    }
    delete this.view.el.fwbOverlayProject;
  }
}
