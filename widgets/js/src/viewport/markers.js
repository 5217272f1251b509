// Markers of a view: one instanced sphere per marker, coloured by state (dragged,
// hovered, selected, mirror), and their page coordinates for tests (data-markers).
//   _markers        bytes, uint32 (h)   marker vertex ids (a tool's, e.g. the model's handles)
//   _marker_mirror  bytes, int32 (h)    mirror marker index or -1 (may be empty)
// Markers are sized by the NEUTRAL mesh's radius (_neutral_bounds), whatever the expression.
// Methods mixed into View.
import * as THREE from "three";
import { MARKER_COLOR, MARKER_HOVER, MARKER_MIRROR, MARKER_SELECTED, typed } from "./util.js";

export const markerMethods = {
  refreshMarkerCache() {
    const ids = typed(this.model.get("_markers"), Uint32Array) || new Uint32Array(0);
    const mirror = typed(this.model.get("_marker_mirror"), Int32Array);
    this.markerIds = ids;
    this.markerMirror = mirror && mirror.length === ids.length ? mirror : null;
    if (this.drag && (this.drag.index >= ids.length || ids[this.drag.index] !== this.drag.vertex)) {
      // The marker set changed under the drag: find the dragged vertex again.
      const k = ids.indexOf(this.drag.vertex);
      if (k >= 0) this.drag.index = k;
    }
    if (this.hover >= ids.length) this.hover = -1;
    this.markersDirty = true;
    if (this.cpuRows) this.cpuRows(ids); // GPU path: the new markers' rows (./gpu_view.js)
  },

  markerRadius() {
    if (!this.markerR) {
      // The neutral mesh's radius: markers are the same size whatever the expression.
      const nb = this.model.get("_neutral_bounds") || {};
      let r = Number(nb.radius);
      if (!(isFinite(r) && r > 0)) {
        if (!this.positionAttr) return 0.014; // no geometry yet: do not cache a guess
        if (!this.geometry.boundingSphere) this.geometry.computeBoundingSphere();
        r = this.geometry.boundingSphere ? this.geometry.boundingSphere.radius : 1;
      }
      this.markerR = (isFinite(r) && r > 0 ? r : 1) * 0.014;
    }
    return this.markerR;
  },

  // World position of marker k: the evaluated vertex, or the pointer target while dragged.
  markerWorld(k, out) {
    const d = this.drag;
    if (d && d.index === k) return out.copy(d.target);
    const P = this.store.positions;
    const n = P ? P.length / 3 : 0;
    const i = Math.min(this.markerIds[k], Math.max(n - 1, 0));
    return P ? out.set(P[3 * i], P[3 * i + 1], P[3 * i + 2]) : out.set(0, 0, 0);
  },

  // The last dragged marker, highlighted while a drag tool is on (-1: none).
  selectedMarker() {
    if (this.toolKind() !== "drag") return -1;
    const sel = this.model.get("selected_marker");
    return sel >= 0 && sel < this.markerIds.length ? sel : -1;
  },

  // Which marker gets the highlight: the dragged one, else the hovered, else the selected.
  activeMarker() {
    if (this.drag) return this.drag.index;
    if (this.hover >= 0) return this.hover;
    return this.selectedMarker();
  },

  updateMarkers() {
    this.markersDirty = false;
    const ids = this.markerIds;
    const P = this.store.positions;
    if (this.markerMesh && this.markerMesh.count !== ids.length) {
      this.scene.remove(this.markerMesh);
      this.markerMesh.geometry.dispose();
      this.markerMesh.material.dispose();
      this.markerMesh = null;
    }
    if (!ids.length || !P) return;
    if (!this.markerMesh) {
      const mesh = new THREE.InstancedMesh(
        // unlit, a few pixels wide: an 80-triangle icosphere reads as the same dot as a
        // 168-triangle UV sphere, and on software WebGL every marker triangle costs
        // (71 handles: ~6k fewer triangles per frame)
        new THREE.IcosahedronGeometry(this.markerRadius(), 1),
        new THREE.MeshBasicMaterial({ color: 0xffffff }),
        ids.length,
      );
      mesh.frustumCulled = false;
      mesh.renderOrder = 1;
      this.markerMesh = mesh;
      this.scene.add(mesh);
    }
    const active = this.activeMarker();
    const dragged = this.drag ? this.drag.index : -1;
    const selected = this.selectedMarker();
    const mirror = this.markerMirror;
    const mirrorOf = this.model.get("symmetric") && mirror && active >= 0 ? mirror[active] : -1;
    const m = new THREE.Matrix4();
    const v = new THREE.Vector3();
    const one = new THREE.Vector3(1, 1, 1);
    const big = new THREE.Vector3(1.4, 1.4, 1.4);
    const q = new THREE.Quaternion();
    const color = new THREE.Color();
    for (let k = 0; k < ids.length; k++) {
      this.markerWorld(k, v);
      const hot = k === dragged || k === this.hover || k === mirrorOf;
      m.compose(v, q, hot ? big : one);
      this.markerMesh.setMatrixAt(k, m);
      let hex = MARKER_COLOR;
      if (k === dragged || (k === selected && k !== this.hover)) hex = MARKER_SELECTED;
      if (k === this.hover && k !== dragged) hex = MARKER_HOVER;
      if (k === mirrorOf) hex = MARKER_MIRROR;
      this.markerMesh.setColorAt(k, color.setHex(hex));
    }
    this.markerMesh.instanceMatrix.needsUpdate = true;
    if (this.markerMesh.instanceColor) this.markerMesh.instanceColor.needsUpdate = true;
  },

  // Page (client) coordinates of the markers, [[x, y, inFront], ...], computed now.
  markerScreenPositions() {
    const ids = this.markerIds;
    if (!ids.length || !this.renderer) return [];
    const v = new THREE.Vector3();
    const rect = this.renderer.domElement.getBoundingClientRect();
    const out = [];
    for (let k = 0; k < ids.length; k++) {
      this.markerWorld(k, v).project(this.camera);
      out.push([
        Math.round((rect.left + ((v.x + 1) / 2) * rect.width) * 10) / 10,
        Math.round((rect.top + ((1 - v.y) / 2) * rect.height) * 10) / 10,
        v.z > -1 && v.z < 1 ? 1 : 0,
      ]);
    }
    return out;
  },

  // Test hook: data-markers = the markers' page coordinates at the last render (the page
  // may have scrolled since: el.fwbMarkers() computes them now).
  writeMarkerHook() {
    const text = JSON.stringify(this.markerScreenPositions());
    if (this.el.getAttribute("data-markers") !== text) this.el.setAttribute("data-markers", text);
  },

  // ---- drag tools: picking ------------------------------------------------------------

};
