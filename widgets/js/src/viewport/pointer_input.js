// Pointer input of a View: the brush cursor, the marker and brush tools (./tools.js) and the
// listeners that feed them, set up and torn down with the view. Methods mixed into View.
//
// Listeners sit on the container in the CAPTURE phase so a press on a handle marker (or on
// the face with the brush) is taken before OrbitControls sees it; Escape cancels a drag or a
// stroke (Python puts its edits back); leaving the canvas clears the hover and the cursor.
import * as THREE from "three";
import { BrushTool, MarkerTool } from "./tools.js";
import { BRUSH_COLOR } from "./util.js";

export const pointerInputMethods = {
  initPointerInput() {
    const el = this.el;
    const renderer = this.renderer;
    const scene = this.scene;
    // Brush cursor: a unit ring in the xy plane, placed on the surface along the normal.
    const ringGeo = new THREE.RingGeometry(0.9, 1.0, 64);
    const ringMat = new THREE.MeshBasicMaterial({
      color: BRUSH_COLOR, transparent: true, opacity: 0.9, depthTest: false, side: THREE.DoubleSide,
    });
    this.brushRing = new THREE.Mesh(ringGeo, ringMat);
    this.brushMirrorRing = new THREE.Mesh(ringGeo, ringMat.clone());
    this.brushMirrorRing.material.opacity = 0.45;
    for (const r of [this.brushRing, this.brushMirrorRing]) {
      r.visible = false;
      r.renderOrder = 2;
      r.frustumCulled = false;
      scene.add(r);
    }

    this.raycaster = new THREE.Raycaster();
    this.drag = null; // the marker drag in progress (MarkerTool)
    this.stroke = null; // the brush stroke in progress (BrushTool)
    this.hover = -1;
    this.tools = { drag: new MarkerTool(this), stroke: new BrushTool(this) };
    // Test/benchmark hook: one entry per acked move {seq, input, send, ack, frame, kernel}
    // (performance.now() ms): input = pointer event, frame = first render showing it.
    this.dragStats = [];
    el.fwbDragStats = this.dragStats;
    // Same for stroke messages: {seq, input, send, ack, frame, kernel, dabs}.
    this.strokeStats = [];
    el.fwbStrokeStats = this.strokeStats;
    const tool = () => (this.stroke || this.toolKind() === "stroke" ? this.tools.stroke : this.tools.drag);
    this.listeners = {
      pointerdown: (e) => {
        if (!this.renderer) return;
        const kind = this.toolKind();
        if (kind === "stroke") this.tools.stroke.down(e);
        else if (kind === "drag") this.tools.drag.down(e);
      },
      pointermove: (e) => tool().move(e),
      pointerup: (e) => tool().up(e),
      pointercancel: (e) => tool().up(e),
    };
    for (const [ev, fn] of Object.entries(this.listeners)) el.addEventListener(ev, fn, true);
    // Escape during a drag or stroke cancels it (Python puts its edits back).
    this.onKey = (e) => {
      if (e.key !== "Escape") return;
      if (this.drag) this.tools.drag.end(null, true);
      if (this.stroke) this.tools.stroke.end(null, true);
    };
    window.addEventListener("keydown", this.onKey);
    this.onLostCapture = (e) => {
      if (this.drag && e.pointerId === this.drag.pointerId) this.tools.drag.end(null);
      if (this.stroke && e.pointerId === this.stroke.pointerId) this.tools.stroke.end(null);
    };
    this.onLeave = () => {
      this.pointerInside = false;
      if (!this.stroke && this.brushRing.visible) {
        this.brushRing.visible = false;
        this.brushMirrorRing.visible = false;
        this.requestRender();
      }
      if (!this.drag) {
        // No marker stays lit once the pointer is elsewhere: neither the hovered one nor
        // the last dragged one (selected_marker, cleared for every view).
        this.clearHover();
        if (this.model.get("selected_marker") >= 0) {
          this.model.set("selected_marker", -1);
          this.model.save_changes();
          this.markersDirty = true;
          this.requestRender();
        }
      }
    };
    renderer.domElement.addEventListener("pointerleave", this.onLeave);
    renderer.domElement.addEventListener("lostpointercapture", this.onLostCapture);
  },

  disposePointerInput() {
    // Never leave Python inside a drag interaction when the view goes away.
    if (this.tools) {
      try { this.tools.drag.end(null); } catch (err) { /* closing */ }
      try { this.tools.stroke.end(null); } catch (err) { /* closing */ }
    }
    if (this.onKey) window.removeEventListener("keydown", this.onKey);
    if (this.listeners) {
      for (const [ev, fn] of Object.entries(this.listeners)) this.el.removeEventListener(ev, fn, true);
    }
    if (this.renderer && this.onLostCapture) {
      this.renderer.domElement.removeEventListener("lostpointercapture", this.onLostCapture);
      this.renderer.domElement.removeEventListener("pointerleave", this.onLeave);
    }
    if (this.brushRing) {
      this.brushRing.geometry.dispose();
      this.brushRing.material.dispose();
      this.brushMirrorRing.material.dispose();
    }
  },
};
