// The pointer tools of a view. Each edit is one gesture (./gestures.js). Which one the
// left button uses follows the kind of the current tool (View.toolKind: the kernel's
// _tool_kinds; method families register the tools, widgets/viewport/tools.py):
//
// MarkerTool (kind "drag"):
//   left-drag on a marker: a "drag" gesture {index, vertex, position: [x, y, z]}; the
//       marker moves in the plane through it perpendicular to the view direction. Python
//       hands it to the tool (or to a panel's drag_handler).
//   {type: "pick", vertex}           Shift-click (or click with add_on_click) on the
//                                    surface: nearest vertex of the hit triangle
//   {type: "unpick", index, vertex}  Alt-click on a marker
//   Orbit/zoom/pan keep working off the markers (and with the right/middle button).
// BrushTool (kind "stroke"):
//   a left press ON the face: a "stroke" gesture {vertices: [v, ...]} (off the face, or
//       with Alt, the left button orbits). Every pointer move raycasts the face; the nearest
//       corner of the hit triangle is queued when it lies a quarter brush radius from the
//       last queued point; the queue (the MAX_QUEUE newest) is the next message's body.
//   stroke_target  what a stroke changes (the tool's target or a stroke handler's); while
//       it is empty a press orbits.
//   brush_radius (model units along the surface) sets the size of the brush cursor: a ring
//   lying on the surface under the pointer (and at the x-mirror with brush_mirror).
// Escape during a drag or stroke cancels it: Python puts its edits back.
import * as THREE from "three";
import { GestureClient } from "./gestures.js";
import { MAX_QUEUE } from "./util.js";

function clientFor(view, kind, body, measure) {
  return new GestureClient(view.model, view.store, kind, {
    body,
    measure,
    onStat: (st) => view.onStat(st),
    onCancel: () => view.tools[kind].stopped(),
  });
}

function capture(view, pointerId, on) {
  try {
    if (on) view.renderer.domElement.setPointerCapture(pointerId);
    else view.renderer.domElement.releasePointerCapture(pointerId);
  } catch (err) { /* synthetic events, or the pointer is gone */ }
}

export class MarkerTool {
  constructor(view) {
    this.view = view;
    this.click = null; // a press that becomes an add/remove click if the pointer stays put
    this.client = clientFor(view, "drag", () => {
      const d = view.drag;
      const t = d.target;
      return { index: d.index, vertex: d.vertex, position: [t.x, t.y, t.z] };
    }, (phase) => (phase === "move" ? {} : null));
  }

  down(e) {
    const view = this.view;
    if (view.drag || e.button !== 0) return; // right / middle button: camera (OrbitControls)
    const k = view.pickMarker(e.clientX, e.clientY, true);
    if (k >= 0 && e.altKey) {
      e.stopPropagation(); e.preventDefault();
      this.click = { kind: "remove", index: k, x: e.clientX, y: e.clientY };
      return;
    }
    if (k >= 0 && !e.shiftKey && !e.ctrlKey && !e.metaKey) {
      e.stopPropagation(); e.preventDefault();
      this.start(k, e);
      return;
    }
    // Off the markers the press goes on to OrbitControls (shift+drag pans); it becomes
    // a "pick" click if the pointer is released where it was pressed.
    if (e.shiftKey || view.model.get("add_on_click")) {
      this.click = { kind: "add", x: e.clientX, y: e.clientY };
    }
  }

  move(e) {
    const view = this.view;
    const d = view.drag;
    if (d) {
      if (e.pointerId !== d.pointerId) return;
      e.stopPropagation(); e.preventDefault();
      // Coalesced events: the last one is the newest position.
      const hit = view.rayPlane(e.clientX, e.clientY, d.plane);
      if (!hit) return;
      d.target.copy(hit).add(d.grab);
      view.predictDrag?.(d); // GPU path: the face follows at once (./gpu_view.js)
      // No render here: the geometry update of this move redraws the marker at its
      // target (a render per pointer event doubled the GPU work of software WebGL
      // and slowed the kernel's round trip on 2 cores); see View.onAck for moves that
      // change no geometry.
      view.markersDirty = true;
      this.client.update(e.timeStamp);
      return;
    }
    if (view.toolKind() !== "drag" || e.buttons !== 0) return;
    view.hoverAt = [e.clientX, e.clientY];
    view.pointerInside = true;
    if (view.hoverPending) return;
    view.hoverPending = true;
    requestAnimationFrame(() => {
      view.hoverPending = false;
      // (a pick queued just before the pointer left must not light a marker again)
      if (!view.renderer || view.drag || !view.pointerInside) return;
      if (view.toolKind() !== "drag") return;
      const k = view.pickMarker(view.hoverAt[0], view.hoverAt[1], false);
      if (k !== view.hover) {
        view.hover = k;
        view.el.setAttribute("data-hover", String(k));
        view.renderer.domElement.style.cursor = k >= 0 ? "grab" : "crosshair";
        view.markersDirty = true;
        view.requestRender();
      }
    });
  }

  up(e) {
    const view = this.view;
    if (view.drag) {
      if (e.pointerId !== view.drag.pointerId) return;
      e.stopPropagation(); e.preventDefault();
      this.end(e);
      return;
    }
    const c = this.click;
    this.click = null;
    if (!c || e.type !== "pointerup" || Math.hypot(e.clientX - c.x, e.clientY - c.y) > 4) return;
    if (c.kind === "remove") {
      e.stopPropagation();
      view.model.send({ type: "unpick", index: c.index, vertex: view.markerIds[c.index] });
    } else {
      const v = view.pickVertex(e.clientX, e.clientY);
      if (v >= 0) view.model.send({ type: "pick", vertex: v });
    }
  }

  start(k, e) {
    const view = this.view;
    const p0 = view.markerWorld(k, new THREE.Vector3());
    const normal = view.camera.getWorldDirection(new THREE.Vector3());
    const plane = new THREE.Plane().setFromNormalAndCoplanarPoint(normal, p0);
    const hit = view.rayPlane(e.clientX, e.clientY, plane) || p0.clone();
    view.drag = {
      index: k,
      vertex: view.markerIds[k],
      plane,
      grab: p0.clone().sub(hit), // keeps the marker from jumping to the pointer
      target: p0.clone(),
      origin: p0.clone(), // where the marker was (the page's prediction: ./gpu_local.js)
      pointerId: e.pointerId,
    };
    view.hover = -1;
    view.controls.enabled = false;
    capture(view, e.pointerId, true);
    view.renderer.domElement.style.cursor = "grabbing";
    view.el.setAttribute("data-dragging", "1");
    this.client.begin(e.timeStamp);
    view.markersDirty = true;
    view.requestRender();
  }

  // Release (e: the pointerup, or null: lost capture, tool change, closing) or Escape.
  end(e, cancel = false) {
    const view = this.view;
    const d = view.drag;
    if (!d) return;
    if (e && e.type === "pointerup") {
      const hit = view.rayPlane(e.clientX, e.clientY, d.plane);
      if (hit) d.target.copy(hit).add(d.grab);
    }
    if (cancel) this.client.cancel(); else this.client.end();
    view.store.endLocalDrag();
    capture(view, d.pointerId, false);
    this.stopped();
  }

  // The drag is over (ended here, or by Python: drag_cancel).
  stopped() {
    const view = this.view;
    if (!view.drag) return;
    view.drag = null;
    view.controls.enabled = true;
    if (view.renderer) {
      view.renderer.domElement.style.cursor = view.toolKind() === "drag" ? "crosshair" : "";
    }
    view.el.setAttribute("data-dragging", "0");
    view.markersDirty = true;
    view.requestRender();
  }
}

export class BrushTool {
  constructor(view) {
    this.view = view;
    this.client = clientFor(view, "stroke", () => {
      const s = view.stroke;
      const vertices = s.queue;
      s.queue = [];
      return { vertices };
    }, (phase, body) => (body.vertices.length ? { dabs: body.vertices.length } : null));
  }

  // Ray hit on the face -> {vertex, point, normal}, or null.
  hit(clientX, clientY) {
    const view = this.view;
    const hit = view.raycastSurface(clientX, clientY);
    if (!hit || !hit.face) return null;
    const A = view.positionAttr.array;
    let best = -1;
    let bestD = Infinity;
    for (const i of [hit.face.a, hit.face.b, hit.face.c]) {
      const d = Math.hypot(A[3 * i] - hit.point.x, A[3 * i + 1] - hit.point.y, A[3 * i + 2] - hit.point.z);
      if (d < bestD) { bestD = d; best = i; }
    }
    const normal = hit.face.normal.clone();
    // Face the camera (the material is double-sided; the back of a lip can be hit).
    if (normal.dot(view.raycaster.ray.direction) > 0) normal.negate();
    return { vertex: best, point: hit.point.clone(), normal };
  }

  placeBrush(hit) {
    const view = this.view;
    const r = Math.max(1e-6, Number(view.model.get("brush_radius")) || 0);
    const z = new THREE.Vector3(0, 0, 1);
    const place = (ring, point, normal) => {
      ring.position.copy(point).addScaledVector(normal, r * 0.02);
      ring.quaternion.setFromUnitVectors(z, normal);
      ring.scale.set(r, r, r);
      ring.visible = true;
    };
    if (!hit) {
      view.brushRing.visible = false;
      view.brushMirrorRing.visible = false;
      return;
    }
    this.brushHit = hit;
    place(view.brushRing, hit.point, hit.normal);
    if (view.model.get("brush_mirror")) {
      const mp = hit.point.clone(); mp.x = -mp.x;
      const mn = hit.normal.clone(); mn.x = -mn.x;
      place(view.brushMirrorRing, mp, mn);
    } else {
      view.brushMirrorRing.visible = false;
    }
  }

  brushSettingsChanged() {
    const view = this.view;
    if (view.brushRing && view.brushRing.visible && this.brushHit) this.placeBrush(this.brushHit);
    view.requestRender();
  }

  brushScreenPosition() {
    const view = this.view;
    if (!view.brushRing || !view.brushRing.visible || !view.renderer) return null;
    const v = view.brushRing.position.clone().project(view.camera);
    const rect = view.renderer.domElement.getBoundingClientRect();
    return [rect.left + ((v.x + 1) / 2) * rect.width, rect.top + ((1 - v.y) / 2) * rect.height];
  }

  down(e) {
    const view = this.view;
    if (view.stroke || e.button !== 0 || e.altKey || e.ctrlKey || e.metaKey) return;
    // Nothing to stroke (the tool has no target, e.g. no expression picked): the press orbits.
    if (!view.model.get("stroke_target")) return;
    const hit = this.hit(e.clientX, e.clientY);
    if (!hit) return; // off the face: OrbitControls gets it
    e.stopPropagation(); e.preventDefault();
    view.stroke = { pointerId: e.pointerId, queue: [hit.vertex], last: hit.point.clone() };
    view.controls.enabled = false;
    capture(view, e.pointerId, true);
    view.el.setAttribute("data-stroking", "1");
    this.placeBrush(hit);
    this.client.begin(e.timeStamp);
    view.requestRender();
  }

  move(e) {
    const view = this.view;
    const s = view.stroke;
    if (s) {
      if (e.pointerId !== s.pointerId) return;
      e.stopPropagation(); e.preventDefault();
      const hit = this.hit(e.clientX, e.clientY);
      if (!hit) return; // slid off the face: no dab, the stroke goes on
      this.placeBrush(hit);
      const r = Number(view.model.get("brush_radius")) || 0;
      if (hit.point.distanceTo(s.last) >= 0.25 * r) {
        s.queue.push(hit.vertex);
        if (s.queue.length > MAX_QUEUE) s.queue.splice(0, s.queue.length - MAX_QUEUE);
        s.last.copy(hit.point);
        // No render here: the dab's overlay/geometry update redraws the cursor too.
        this.client.update(e.timeStamp);
      }
      return;
    }
    if (e.buttons !== 0) return; // orbiting
    view.hoverAt = [e.clientX, e.clientY];
    if (view.hoverPending) return;
    view.hoverPending = true;
    requestAnimationFrame(() => {
      view.hoverPending = false;
      if (!view.renderer || view.stroke || view.toolKind() !== "stroke") return;
      this.placeBrush(this.hit(view.hoverAt[0], view.hoverAt[1]));
      view.requestRender();
    });
  }

  up(e) {
    const s = this.view.stroke;
    if (!s || e.pointerId !== s.pointerId) return;
    e.stopPropagation(); e.preventDefault();
    this.end(e);
  }

  end(e, cancel = false) {
    const view = this.view;
    const s = view.stroke;
    if (!s) return;
    if (e && e.type === "pointerup") {
      const hit = this.hit(e.clientX, e.clientY);
      const r = Number(view.model.get("brush_radius")) || 0;
      if (hit && hit.point.distanceTo(s.last) >= 0.25 * r) s.queue.push(hit.vertex);
    }
    if (cancel) this.client.cancel(); else this.client.end();
    capture(view, s.pointerId, false);
    this.stopped();
  }

  stopped() {
    const view = this.view;
    if (!view.stroke) return;
    view.stroke = null;
    view.controls.enabled = true;
    view.el.setAttribute("data-stroking", "0");
    view.requestRender();
  }
}
