// Front end of widgets.Viewport: draws the FaceModel's evaluated vertices with three.js.
//
// Why hand-written instead of an off-the-shelf viewer (pythreejs, pyvista's trame backend):
// the workbench needs binary, partial geometry updates (only the vertices a slider moved),
// camera orbit that never touches the kernel, and test hooks (data-* attributes) that
// browser tests use to aim the mouse and to wait for frames. None of the existing widgets
// give all three; this file is small and has no dependency but three.js.
//
// Data flow (see widgets/viewport.py for the Python side):
//   _faces      bytes, uint32 (m*3)   sent once
//   _positions  bytes, float32 (n*3)  full buffer, when many vertices changed (or on load)
//   _labels     bytes, uint16 (n)     component index per vertex
//   msg:custom  {type: "patch", version}, buffers [ids uint32 (k), values float32 (k*3)]
//               when fewer than ~1/3 of the vertices changed
//   _handles        bytes, uint32 (h)   handle marker vertex ids (the model's handles)
//   _handle_mirror  bytes, int32 (h)    mirror handle index or -1 (may be empty)
//
// Sculpt tool (tool == "sculpt", Bickel et al. 2008 §4 handle editing), front end -> Python:
//   {type: "handle", phase: "start"|"move"|"end", index, vertex, position: [x,y,z], seq}
//       left-drag on a marker; the marker moves in the plane through it perpendicular to
//       the view direction. At most ONE "move" is in flight: the next one (the newest
//       pointer position) is sent when Python's {type: "handle_ack", seq} arrives, so a
//       slow kernel sees fewer, not queued-up, updates.
//   {type: "add_handle", vertex}            Shift-click (or click with add_on_click) on
//                                           the surface: nearest vertex of the hit triangle
//   {type: "remove_handle", index, vertex}  Alt-click on a marker
// Orbit/zoom/pan keep working off the markers (and with the right/middle button).
// All views of one widget model share one geometry store (state lives in the model,
// not in the view), so a second display of the same widget shows the same frame.

import * as THREE from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";

// ---------------------------------------------------------------------------------------
// binary helpers: the widget protocol hands us DataView (state) or DataView/ArrayBuffer
// (custom message buffers); typed-array views need aligned offsets, so copy if unaligned.

function typed(value, Ctor) {
  if (value == null) return null;
  let buf, off, len;
  if (value instanceof ArrayBuffer) {
    buf = value; off = 0; len = value.byteLength;
  } else if (ArrayBuffer.isView(value)) {
    buf = value.buffer; off = value.byteOffset; len = value.byteLength;
  } else {
    return null;
  }
  if (len === 0) return new Ctor(0);
  if (off % Ctor.BYTES_PER_ELEMENT !== 0) {
    const copy = new Uint8Array(len);
    copy.set(new Uint8Array(buf, off, len));
    buf = copy.buffer; off = 0;
  }
  return new Ctor(buf, off, Math.floor(len / Ctor.BYTES_PER_ELEMENT));
}

// Smooth (area-weighted) vertex normals over ALL faces (hidden components included, so
// normals do not change when a component is hidden). A flat typed-array loop: about 4x
// faster than BufferGeometry.computeVertexNormals(), which allocates Vector3 work per face;
// at 80k vertices that is most of the per-frame cost.
function computeNormals(P, F, N) {
  N.fill(0);
  for (let f = 0; f < F.length; f += 3) {
    const a = 3 * F[f], b = 3 * F[f + 1], c = 3 * F[f + 2];
    const e1x = P[b] - P[a], e1y = P[b + 1] - P[a + 1], e1z = P[b + 2] - P[a + 2];
    const e2x = P[c] - P[a], e2y = P[c + 1] - P[a + 1], e2z = P[c + 2] - P[a + 2];
    const nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z, nz = e1x * e2y - e1y * e2x;
    N[a] += nx; N[a + 1] += ny; N[a + 2] += nz;
    N[b] += nx; N[b + 1] += ny; N[b + 2] += nz;
    N[c] += nx; N[c + 1] += ny; N[c + 2] += nz;
  }
  for (let i = 0; i < N.length; i += 3) {
    const l = Math.hypot(N[i], N[i + 1], N[i + 2]) || 1;
    N[i] /= l; N[i + 1] /= l; N[i + 2] /= l;
  }
}

// Default colours per component name (sRGB). Anything unknown is drawn as skin.
const COMPONENT_COLORS = [
  [/^skin|head|face|body/i, [0.86, 0.68, 0.58]],
  [/eyelash|brow_hair|eyebrow/i, [0.12, 0.09, 0.07]],
  [/iris|pupil|cornea/i, [0.25, 0.35, 0.45]],
  [/eye/i, [0.93, 0.93, 0.9]],
  [/teeth|tooth/i, [0.95, 0.93, 0.85]],
  [/tongue/i, [0.8, 0.4, 0.42]],
  [/gum/i, [0.85, 0.45, 0.45]],
];
const SKIN = [0.86, 0.68, 0.58];

// Handle marker colours (sRGB): idle, hovered, dragged/selected, mirror of the active one.
const HANDLE_COLOR = 0xff8c1a;
const HANDLE_HOVER = 0xffe14d;
const HANDLE_SELECTED = 0x2ee6ff;
const HANDLE_MIRROR = 0xd17aff;

function colorForComponent(name) {
  for (const [re, rgb] of COMPONENT_COLORS) if (re.test(name || "")) return rgb;
  return SKIN;
}

function srgbToLinear(c) {
  return c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4);
}

// ---------------------------------------------------------------------------------------
// Geometry store: one per widget model, shared by its views.

class Store {
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

// ---------------------------------------------------------------------------------------
// One view: renderer, scene, camera, controls, test hooks.

class View {
  constructor(store, model, el) {
    this.store = store;
    this.model = model;
    this.el = el;
    this.frame = 0; // rendered geometry updates (test hook data-frame)
    this.renders = 0; // all renders (orbit included)
    this.pending = false;
    this.geometryDirty = true;
    this.seenTopology = -1;
    this.seenPositions = -1;
    this.framed = false;
    this.build();
  }

  build() {
    const el = this.el;
    el.classList.add("fwb-viewport");
    el.style.position = "relative";
    el.style.width = "100%";
    el.style.minWidth = "240px";
    el.style.height = `${this.model.get("height")}px`;
    el.setAttribute("data-frame", "0");
    el.setAttribute("data-render-count", "0");
    el.setAttribute("data-vertex-count", "0");
    el.setAttribute("data-ready", "0");

    let renderer;
    try {
      renderer = new THREE.WebGLRenderer({
        antialias: true,
        // Keeps the last frame readable (screenshots, toDataURL) after compositing.
        preserveDrawingBuffer: true,
      });
    } catch (err) {
      el.textContent = `WebGL is not available in this browser: ${err}`;
      el.setAttribute("data-error", String(err));
      this.renderer = null;
      return;
    }
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    renderer.setClearColor(0x2b2f36, 1);
    renderer.outputColorSpace = THREE.SRGBColorSpace;
    this.renderer = renderer;
    renderer.domElement.style.display = "block";
    renderer.domElement.style.touchAction = "none";
    el.appendChild(renderer.domElement);

    this.banner = document.createElement("div");
    Object.assign(this.banner.style, {
      position: "absolute", left: "0", right: "0", top: "0", padding: "4px 8px",
      background: "rgba(160,20,20,0.85)", color: "white", font: "12px monospace",
      whiteSpace: "pre-wrap", display: "none", pointerEvents: "none",
    });
    el.appendChild(this.banner);

    const scene = new THREE.Scene();
    this.scene = scene;
    const camera = new THREE.PerspectiveCamera(30, 1, 0.01, 1000);
    this.camera = camera;
    scene.add(camera);
    scene.add(new THREE.HemisphereLight(0xffffff, 0x3a3530, 1.2));
    // Key light rides with the camera so the face stays lit from wherever it is seen.
    const key = new THREE.DirectionalLight(0xffffff, 2.2);
    key.position.set(0.6, 0.8, 1.0);
    camera.add(key);
    camera.add(key.target);
    key.target.position.set(0, 0, -1);

    this.geometry = new THREE.BufferGeometry();
    this.material = new THREE.MeshStandardMaterial({
      vertexColors: true,
      roughness: 0.62,
      metalness: 0.0,
      side: THREE.DoubleSide,
      polygonOffset: true, // lets the wireframe overlay win the depth test
      polygonOffsetFactor: 1,
      polygonOffsetUnits: 1,
    });
    this.mesh = new THREE.Mesh(this.geometry, this.material);
    this.mesh.frustumCulled = false;
    scene.add(this.mesh);
    this.wireMaterial = new THREE.MeshBasicMaterial({
      color: 0x101418, wireframe: true, transparent: true, opacity: 0.35,
    });
    this.wire = new THREE.Mesh(this.geometry, this.wireMaterial);
    this.wire.frustumCulled = false;
    this.wire.visible = false;
    scene.add(this.wire);
    this.handleMesh = null;
    this.handlesDirty = true;
    this.refreshHandleCache();

    const controls = new OrbitControls(camera, renderer.domElement);
    controls.enableDamping = false; // render on demand only: no animation loop
    controls.addEventListener("change", () => this.requestRender(false));
    this.controls = controls;

    // Sculpt tool state. Listeners sit on the container in the CAPTURE phase so a press
    // on a handle marker is taken before OrbitControls (on the canvas) sees it.
    this.raycaster = new THREE.Raycaster();
    this.drag = null; // the handle drag in progress
    this.click = null; // a press that becomes an add/remove click if the pointer stays put
    this.hover = -1;
    this.seq = 0;
    this.pendingStats = new Map(); // seq -> timing of a move waiting for its ack
    this.awaitFrame = []; // acked moves waiting for the frame that shows them
    this.renderedVersion = -1;
    this.renderedTime = 0;
    // Test/benchmark hook: one entry per acked move {seq, input, send, ack, frame, kernel}
    // (performance.now() ms): input = pointer event, frame = first render showing it.
    this.dragStats = [];
    el.fwbDragStats = this.dragStats;
    this.listeners = {
      pointerdown: (e) => this.onPointerDown(e),
      pointermove: (e) => this.onPointerMove(e),
      pointerup: (e) => this.onPointerUp(e),
      pointercancel: (e) => this.onPointerUp(e),
    };
    for (const [ev, fn] of Object.entries(this.listeners)) el.addEventListener(ev, fn, true);
    this.onLostCapture = (e) => {
      if (this.drag && e.pointerId === this.drag.pointerId) this.endDrag(null);
    };
    renderer.domElement.addEventListener("lostpointercapture", this.onLostCapture);
    this.updateTool();

    this.resizeObserver = new ResizeObserver(() => this.resize());
    this.resizeObserver.observe(el);

    // Test hook: screen (client) coordinates of vertex ids, [[x, y, inFront], ...].
    el.fwbProject = (ids) => this.project(ids);
    el.fwbHandles = () => this.handleScreenPositions();

    this.resize();
    this.syncAll();
  }

  syncAll() {
    this.updateTool();
    this.updateWireframe();
    this.updateError();
    this.geometryChanged();
  }

  geometryChanged() {
    this.geometryDirty = true;
    this.requestRender(true);
  }

  requestRender() {
    if (this.pending || !this.renderer) return;
    this.pending = true;
    // Coalesce: many patches within one display frame cost one render.
    requestAnimationFrame(() => {
      this.pending = false;
      this.renderNow();
    });
  }

  // ---- geometry -----------------------------------------------------------------------

  uploadGeometry() {
    const s = this.store;
    if (!s.positions || !s.faces) return false;
    const g = this.geometry;
    const n = s.positions.length / 3;
    if (this.seenTopology !== s.topologyVersion) {
      this.positionAttr = new THREE.BufferAttribute(new Float32Array(s.positions), 3);
      this.positionAttr.setUsage(THREE.DynamicDrawUsage);
      g.setAttribute("position", this.positionAttr);
      g.setAttribute("normal", new THREE.BufferAttribute(new Float32Array(n * 3), 3));
      g.setAttribute("color", new THREE.BufferAttribute(new Float32Array(n * 3), 3));
      this.seenTopology = s.topologyVersion;
      this.updateIndex();
      this.updateColors();
      this.el.setAttribute("data-vertex-count", String(n));
      this.el.setAttribute("data-face-count", String(s.faces.length / 3));
    } else {
      const arr = this.positionAttr.array;
      const ids = s.lastPatchIds;
      if (ids && this.seenPositions === s.positionsVersion - 1) {
        // Only the patched vertices changed since our last upload.
        const P = s.positions;
        for (let k = 0; k < ids.length; k++) {
          const j = 3 * ids[k];
          arr[j] = P[j]; arr[j + 1] = P[j + 1]; arr[j + 2] = P[j + 2];
        }
      } else {
        arr.set(s.positions);
      }
      this.positionAttr.needsUpdate = true;
    }
    this.seenPositions = s.positionsVersion;
    // smooth shading: normals always from the current positions
    const normals = g.getAttribute("normal");
    computeNormals(this.positionAttr.array, s.faces, normals.array);
    normals.needsUpdate = true;
    if (!this.framed) g.computeBoundingSphere();
    if (!this.framed) this.frameCamera();
    this.updateHandles();
    return true;
  }

  updateIndex() {
    const s = this.store;
    if (!s.faces) return;
    const names = this.model.get("_component_names") || [];
    const visible = this.model.get("component_visible") || {};
    let faces = s.faces;
    const hidden = names.map((nm) => visible[nm] === false);
    if (s.labels && hidden.some((h) => h)) {
      const keep = [];
      const L = s.labels;
      for (let f = 0; f < faces.length; f += 3) {
        if (!hidden[L[faces[f]]]) keep.push(faces[f], faces[f + 1], faces[f + 2]);
      }
      faces = new Uint32Array(keep);
    }
    this.geometry.setIndex(new THREE.BufferAttribute(faces, 1));
  }

  updateColors() {
    const s = this.store;
    const attr = this.geometry.getAttribute("color");
    if (!attr || !s.positions) return;
    const n = s.positions.length / 3;
    const C = attr.array;
    const overlay = typed(this.model.get("_vertex_colors"), Float32Array);
    if (overlay && overlay.length === n * 3) {
      // Overlay values are sRGB in [0, 1] (what a user picks); the shader wants linear.
      for (let i = 0; i < n * 3; i++) C[i] = srgbToLinear(Math.min(1, Math.max(0, overlay[i])));
    } else {
      const names = this.model.get("_component_names") || [];
      const table = names.map((nm) => colorForComponent(nm).map(srgbToLinear));
      const skin = SKIN.map(srgbToLinear);
      const L = s.labels;
      for (let i = 0; i < n; i++) {
        const rgb = (L && table[L[i]]) || skin;
        C[3 * i] = rgb[0]; C[3 * i + 1] = rgb[1]; C[3 * i + 2] = rgb[2];
      }
    }
    attr.needsUpdate = true;
  }

  updateWireframe() {
    if (this.wire) this.wire.visible = !!this.model.get("wireframe");
  }

  updateError() {
    if (!this.banner) return;
    const msg = this.model.get("_error") || "";
    this.banner.textContent = msg;
    this.banner.style.display = msg ? "block" : "none";
    this.el.setAttribute("data-error", msg);
  }

  // ---- handle markers ----------------------------------------------------------------

  refreshHandleCache() {
    const ids = typed(this.model.get("_handles"), Uint32Array) || new Uint32Array(0);
    const mirror = typed(this.model.get("_handle_mirror"), Int32Array);
    this.handleIds = ids;
    this.handleMirror = mirror && mirror.length === ids.length ? mirror : null;
    if (this.drag && (this.drag.index >= ids.length || ids[this.drag.index] !== this.drag.vertex)) {
      // The handle set changed under the drag: find the dragged vertex again.
      const k = ids.indexOf(this.drag.vertex);
      if (k >= 0) this.drag.index = k;
    }
    if (this.hover >= ids.length) this.hover = -1;
    this.handlesDirty = true;
  }

  markerRadius() {
    if (!this.positionAttr) return 0.014; // no geometry yet: do not cache a guess
    if (!this.markerR) {
      if (!this.geometry.boundingSphere) this.geometry.computeBoundingSphere();
      const r = this.geometry.boundingSphere ? this.geometry.boundingSphere.radius : 1;
      this.markerR = (isFinite(r) && r > 0 ? r : 1) * 0.014;
    }
    return this.markerR;
  }

  // World position of marker k: the evaluated vertex, or the pointer target while dragged.
  markerWorld(k, out) {
    const d = this.drag;
    if (d && d.index === k) return out.copy(d.target);
    const P = this.store.positions;
    const n = P ? P.length / 3 : 0;
    const i = Math.min(this.handleIds[k], Math.max(n - 1, 0));
    return P ? out.set(P[3 * i], P[3 * i + 1], P[3 * i + 2]) : out.set(0, 0, 0);
  }

  // Which marker gets the highlight: the dragged one, else the hovered, else the selected.
  activeHandle() {
    if (this.drag) return this.drag.index;
    if (this.hover >= 0) return this.hover;
    const sel = this.model.get("selected_handle");
    return sel >= 0 && sel < this.handleIds.length ? sel : -1;
  }

  updateHandles() {
    this.handlesDirty = false;
    const ids = this.handleIds;
    const P = this.store.positions;
    if (this.handleMesh && this.handleMesh.count !== ids.length) {
      this.scene.remove(this.handleMesh);
      this.handleMesh.geometry.dispose();
      this.handleMesh.material.dispose();
      this.handleMesh = null;
    }
    if (!ids.length || !P) return;
    if (!this.handleMesh) {
      const mesh = new THREE.InstancedMesh(
        new THREE.SphereGeometry(this.markerRadius(), 12, 8),
        new THREE.MeshBasicMaterial({ color: 0xffffff }),
        ids.length,
      );
      mesh.frustumCulled = false;
      mesh.renderOrder = 1;
      this.handleMesh = mesh;
      this.scene.add(mesh);
    }
    const active = this.activeHandle();
    const dragged = this.drag ? this.drag.index : -1;
    const selected = this.model.get("selected_handle");
    const mirror = this.handleMirror;
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
      this.handleMesh.setMatrixAt(k, m);
      let hex = HANDLE_COLOR;
      if (k === dragged || (k === selected && k !== this.hover)) hex = HANDLE_SELECTED;
      if (k === this.hover && k !== dragged) hex = HANDLE_HOVER;
      if (k === mirrorOf) hex = HANDLE_MIRROR;
      this.handleMesh.setColorAt(k, color.setHex(hex));
    }
    this.handleMesh.instanceMatrix.needsUpdate = true;
    if (this.handleMesh.instanceColor) this.handleMesh.instanceColor.needsUpdate = true;
  }

  // Page (client) coordinates of the markers, [[x, y, inFront], ...], computed now.
  handleScreenPositions() {
    const ids = this.handleIds;
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
  }

  // Test hook: data-handles = the markers' page coordinates at the last render (the page
  // may have scrolled since: el.fwbHandles() computes them now).
  writeHandleHook() {
    const text = JSON.stringify(this.handleScreenPositions());
    if (this.el.getAttribute("data-handles") !== text) this.el.setAttribute("data-handles", text);
  }

  // ---- sculpt tool: picking -----------------------------------------------------------

  updateTool() {
    const sculpt = this.model.get("tool") === "sculpt";
    this.el.setAttribute("data-tool", sculpt ? "sculpt" : "orbit");
    if (!sculpt) {
      if (this.drag) this.endDrag(null);
      this.hover = -1;
      this.click = null;
    }
    if (this.renderer) this.renderer.domElement.style.cursor = sculpt ? "crosshair" : "";
    this.handlesDirty = true;
    this.requestRender();
  }

  ndc(clientX, clientY) {
    const rect = this.renderer.domElement.getBoundingClientRect();
    return new THREE.Vector2(
      ((clientX - rect.left) / rect.width) * 2 - 1,
      -((clientY - rect.top) / rect.height) * 2 + 1,
    );
  }

  // Marker under the pointer (screen distance, nearest first), or -1. With `visible`,
  // markers hidden behind the surface (seen from the back of the head) are skipped.
  pickHandle(clientX, clientY, visible) {
    const ids = this.handleIds;
    if (!ids.length || !this.store.positions) return -1;
    const rect = this.renderer.domElement.getBoundingClientRect();
    const tanHalf = Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2));
    const r = this.markerRadius();
    const v = new THREE.Vector3();
    const cands = [];
    for (let k = 0; k < ids.length; k++) {
      this.markerWorld(k, v);
      const dist = v.distanceTo(this.camera.position);
      v.project(this.camera);
      if (v.z < -1 || v.z > 1) continue;
      const sx = rect.left + ((v.x + 1) / 2) * rect.width;
      const sy = rect.top + ((1 - v.y) / 2) * rect.height;
      const d = Math.hypot(sx - clientX, sy - clientY);
      const rpx = (r / (dist * tanHalf)) * (rect.height / 2);
      if (d <= Math.max(8, 1.6 * rpx + 3)) cands.push({ k, d, dist });
    }
    if (!cands.length) return -1;
    cands.sort((a, b) => a.d - b.d);
    if (!visible) return cands[0].k;
    const hit = this.raycastSurface(clientX, clientY);
    for (const c of cands) {
      if (!hit || hit.distance >= c.dist - 4 * r) return c.k;
    }
    return -1;
  }

  raycastSurface(clientX, clientY) {
    if (!this.positionAttr) return null;
    // The face deforms: bounds from the current positions, else rays near the edge miss.
    this.geometry.computeBoundingSphere();
    this.geometry.boundingBox = null;
    this.raycaster.setFromCamera(this.ndc(clientX, clientY), this.camera);
    const hits = this.raycaster.intersectObject(this.mesh, false);
    return hits.length ? hits[0] : null;
  }

  // Nearest vertex of the triangle under the pointer, or -1.
  pickVertex(clientX, clientY) {
    const hit = this.raycastSurface(clientX, clientY);
    if (!hit || !hit.face) return -1;
    const A = this.positionAttr.array;
    let best = -1;
    let bestD = Infinity;
    for (const i of [hit.face.a, hit.face.b, hit.face.c]) {
      const d = Math.hypot(A[3 * i] - hit.point.x, A[3 * i + 1] - hit.point.y, A[3 * i + 2] - hit.point.z);
      if (d < bestD) { bestD = d; best = i; }
    }
    return best;
  }

  rayPlane(clientX, clientY, plane) {
    this.raycaster.setFromCamera(this.ndc(clientX, clientY), this.camera);
    return this.raycaster.ray.intersectPlane(plane, new THREE.Vector3());
  }

  // ---- sculpt tool: pointer events ----------------------------------------------------

  onPointerDown(e) {
    if (!this.renderer || this.model.get("tool") !== "sculpt" || this.drag) return;
    if (e.button !== 0) return; // right / middle button: camera (OrbitControls)
    const k = this.pickHandle(e.clientX, e.clientY, true);
    if (k >= 0 && e.altKey) {
      e.stopPropagation(); e.preventDefault();
      this.click = { kind: "remove", index: k, x: e.clientX, y: e.clientY };
      return;
    }
    if (k >= 0 && !e.shiftKey && !e.ctrlKey && !e.metaKey) {
      e.stopPropagation(); e.preventDefault();
      this.startDrag(k, e);
      return;
    }
    // Off the markers the press goes on to OrbitControls (shift+drag pans); it becomes
    // an "add handle" click if the pointer is released where it was pressed.
    if (e.shiftKey || this.model.get("add_on_click")) {
      this.click = { kind: "add", x: e.clientX, y: e.clientY };
    }
  }

  onPointerMove(e) {
    const d = this.drag;
    if (d) {
      if (e.pointerId !== d.pointerId) return;
      e.stopPropagation(); e.preventDefault();
      // Coalesced events: the last one is the newest position.
      const hit = this.rayPlane(e.clientX, e.clientY, d.plane);
      if (!hit) return;
      d.target.copy(hit).add(d.grab);
      d.dirty = true;
      d.inputTime = e.timeStamp;
      // No render here: the geometry update of this move redraws the marker at its
      // target (a render per pointer event doubled the GPU work of software WebGL
      // and slowed the kernel's round trip on 2 cores); see onAck for moves that
      // change no geometry.
      this.handlesDirty = true;
      this.flushDrag();
      return;
    }
    if (this.model.get("tool") !== "sculpt" || e.buttons !== 0) return;
    this.hoverAt = [e.clientX, e.clientY];
    if (this.hoverPending) return;
    this.hoverPending = true;
    requestAnimationFrame(() => {
      this.hoverPending = false;
      if (!this.renderer || this.drag || this.model.get("tool") !== "sculpt") return;
      const k = this.pickHandle(this.hoverAt[0], this.hoverAt[1], false);
      if (k !== this.hover) {
        this.hover = k;
        this.el.setAttribute("data-hover", String(k));
        this.renderer.domElement.style.cursor = k >= 0 ? "grab" : "crosshair";
        this.handlesDirty = true;
        this.requestRender();
      }
    });
  }

  onPointerUp(e) {
    if (this.drag) {
      if (e.pointerId !== this.drag.pointerId) return;
      e.stopPropagation(); e.preventDefault();
      this.endDrag(e);
      return;
    }
    const c = this.click;
    this.click = null;
    if (!c || e.type !== "pointerup" || Math.hypot(e.clientX - c.x, e.clientY - c.y) > 4) return;
    if (c.kind === "remove") {
      e.stopPropagation();
      this.model.send({ type: "remove_handle", index: c.index, vertex: this.handleIds[c.index] });
    } else {
      const v = this.pickVertex(e.clientX, e.clientY);
      if (v >= 0) this.model.send({ type: "add_handle", vertex: v });
    }
  }

  // ---- sculpt tool: the drag ----------------------------------------------------------

  startDrag(k, e) {
    const p0 = this.markerWorld(k, new THREE.Vector3());
    const normal = this.camera.getWorldDirection(new THREE.Vector3());
    const plane = new THREE.Plane().setFromNormalAndCoplanarPoint(normal, p0);
    const hit = this.rayPlane(e.clientX, e.clientY, plane) || p0.clone();
    this.drag = {
      index: k,
      vertex: this.handleIds[k],
      plane,
      grab: p0.clone().sub(hit), // keeps the marker from jumping to the pointer
      target: p0.clone(),
      pointerId: e.pointerId,
      inFlight: 0,
      sentAt: 0,
      dirty: false,
      inputTime: e.timeStamp,
    };
    this.hover = -1;
    this.controls.enabled = false;
    try { this.renderer.domElement.setPointerCapture(e.pointerId); } catch (err) { /* synthetic */ }
    this.renderer.domElement.style.cursor = "grabbing";
    this.el.setAttribute("data-dragging", "1");
    this.sendHandle("start");
    this.handlesDirty = true;
    this.requestRender();
  }

  sendHandle(phase) {
    const d = this.drag;
    this.seq += 1;
    const t = d.target;
    this.model.send({
      type: "handle", phase, index: d.index, vertex: d.vertex,
      position: [t.x, t.y, t.z], seq: this.seq,
    });
    if (phase === "move") {
      d.inFlight = this.seq;
      d.sentAt = performance.now();
      this.pendingStats.set(this.seq, { seq: this.seq, input: d.inputTime, send: d.sentAt });
    }
  }

  // Send the newest target unless a move is still in flight (or lost for 2 s).
  flushDrag() {
    const d = this.drag;
    if (!d || !d.dirty) return;
    if (d.inFlight && performance.now() - d.sentAt < 2000) return;
    d.dirty = false;
    this.sendHandle("move");
  }

  endDrag(e) {
    const d = this.drag;
    if (!d) return;
    if (e && e.type === "pointerup") {
      const hit = this.rayPlane(e.clientX, e.clientY, d.plane);
      if (hit) d.target.copy(hit).add(d.grab);
    }
    this.sendHandle("end");
    this.drag = null;
    this.controls.enabled = true;
    try { this.renderer.domElement.releasePointerCapture(d.pointerId); } catch (err) { /* gone */ }
    this.renderer.domElement.style.cursor = this.model.get("tool") === "sculpt" ? "crosshair" : "";
    this.el.setAttribute("data-dragging", "0");
    this.handlesDirty = true;
    this.requestRender();
  }

  cancelDrag() {
    if (!this.drag) return;
    this.drag = null;
    this.controls.enabled = true;
    this.el.setAttribute("data-dragging", "0");
    this.handlesDirty = true;
    this.requestRender();
  }

  onAck(content) {
    const now = performance.now();
    const st = this.pendingStats.get(content.seq);
    if (st) {
      this.pendingStats.delete(content.seq);
      st.ack = now;
      st.kernel = content.kernel_ms != null ? content.kernel_ms : null;
      st.version = content.version;
      // The geometry of this move arrived before its ack (same channel, in order).
      if (this.renderedVersion >= content.version && !this.geometryDirty) {
        this.finishStat(st, this.renderedTime);
      } else {
        this.awaitFrame.push(st);
      }
    }
    const d = this.drag;
    if (d && d.inFlight === content.seq) {
      d.inFlight = 0;
      this.flushDrag();
    }
    // A move that changed no geometry still moved the marker.
    if (this.handlesDirty && !this.geometryDirty) this.requestRender();
  }

  finishStat(st, frameTime) {
    // A move that changed nothing shows no new frame: no latency to report.
    st.frame = frameTime >= st.input ? frameTime : null;
    this.dragStats.push(st);
    if (this.dragStats.length > 4000) this.dragStats.splice(0, 2000);
    this.el.setAttribute("data-drag-updates", String(this.dragStats.length));
  }

  frameCamera() {
    const sphere = this.geometry.boundingSphere;
    if (!sphere || !isFinite(sphere.radius) || sphere.radius <= 0) return;
    // Frame the bounding box of the skin only if it exists: eyes/teeth are inside anyway.
    const box = new THREE.Box3().setFromBufferAttribute(this.geometry.getAttribute("position"));
    const center = box.getCenter(new THREE.Vector3());
    const size = box.getSize(new THREE.Vector3());
    const up = this.model.get("_up_axis") || "+y";
    const cam = this.camera;
    const half = THREE.MathUtils.degToRad(cam.fov / 2);
    let dir; // direction from target to camera: the face looks toward +z (y up)
    if (up === "+z") {
      cam.up.set(0, 0, 1);
      dir = new THREE.Vector3(0, -1, 0);
    } else {
      cam.up.set(0, 1, 0);
      dir = new THREE.Vector3(0, 0, 1);
    }
    const extentV = up === "+z" ? size.z : size.y;
    const extentH = size.x;
    const aspect = cam.aspect || 1;
    const needV = extentV / 2 / Math.tan(half);
    const needH = extentH / 2 / (Math.tan(half) * aspect);
    const depth = up === "+z" ? size.y : size.z;
    const dist = Math.max(needV, needH) * 1.04 + depth * 0.3;
    cam.position.copy(center).addScaledVector(dir, dist);
    cam.near = Math.max(dist / 100, 1e-4);
    cam.far = dist * 100;
    cam.updateProjectionMatrix();
    this.controls.target.copy(center);
    this.controls.update();
    this.framed = true;
  }

  resize() {
    if (!this.renderer) return;
    const w = Math.max(this.el.clientWidth, 240);
    const h = this.model.get("height");
    this.el.style.height = `${h}px`;
    this.renderer.setSize(w, h, true);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.requestRender(false);
  }

  renderNow() {
    const t0 = performance.now();
    let newGeometry = false;
    if (this.geometryDirty) {
      this.geometryDirty = false;
      newGeometry = this.uploadGeometry();
    } else if (this.handlesDirty) {
      this.updateHandles();
    }
    this.renderer.render(this.scene, this.camera);
    this.renders += 1;
    const el = this.el;
    el.setAttribute("data-render-count", String(this.renders));
    if (newGeometry) {
      this.frame += 1;
      el.setAttribute("data-frame", String(this.frame));
      el.setAttribute("data-version", String(this.store.version));
      // performance.now() of the render that first showed this geometry (latency bench).
      const t1 = performance.now();
      el.setAttribute("data-frame-time", String(t1));
      // upload + normals + draw-call time of this frame (benchmark breakdown)
      el.setAttribute("data-render-ms", (t1 - t0).toFixed(2));
      // when the geometry message arrived (benchmark: transport vs. wait-for-frame)
      el.setAttribute("data-update-time", String(this.store.lastUpdateTime || 0));
      el.setAttribute("data-ready", "1");
      this.renderedVersion = this.store.version;
      this.renderedTime = t1;
      if (this.awaitFrame.length) {
        const keep = [];
        for (const st of this.awaitFrame) {
          if (st.version <= this.renderedVersion) this.finishStat(st, t1); else keep.push(st);
        }
        this.awaitFrame = keep;
      }
    }
    this.writeProbe();
    this.writeHandleHook();
  }

  // ---- test hooks ---------------------------------------------------------------------

  project(ids) {
    const P = this.store.positions;
    if (!P || !this.renderer) return [];
    const rect = this.renderer.domElement.getBoundingClientRect();
    const v = new THREE.Vector3();
    const n = P.length / 3;
    const out = [];
    for (const id of ids) {
      if (id < 0 || id >= n) { out.push(null); continue; }
      v.set(P[3 * id], P[3 * id + 1], P[3 * id + 2]).project(this.camera);
      out.push([
        rect.left + ((v.x + 1) / 2) * rect.width,
        rect.top + ((1 - v.y) / 2) * rect.height,
        v.z > -1 && v.z < 1 ? 1 : 0,
      ]);
    }
    return out;
  }

  writeProbe() {
    const ids = typed(this.model.get("_probe_ids"), Uint32Array);
    if (!ids || !ids.length) return;
    const pts = this.project(Array.from(ids)).map((p) =>
      p ? [Math.round(p[0] * 10) / 10, Math.round(p[1] * 10) / 10, p[2]] : null);
    this.el.setAttribute("data-probe", JSON.stringify(pts));
  }

  dispose() {
    // Never leave Python inside a drag interaction when the view goes away.
    if (this.drag) { try { this.endDrag(null); } catch (err) { /* closing */ } }
    if (this.listeners) {
      for (const [ev, fn] of Object.entries(this.listeners)) this.el.removeEventListener(ev, fn, true);
    }
    if (this.renderer && this.onLostCapture) {
      this.renderer.domElement.removeEventListener("lostpointercapture", this.onLostCapture);
    }
    if (this.resizeObserver) this.resizeObserver.disconnect();
    if (this.controls) this.controls.dispose();
    if (this.handleMesh) this.handleMesh.geometry.dispose();
    if (this.geometry) this.geometry.dispose();
    if (this.material) this.material.dispose();
    if (this.wireMaterial) this.wireMaterial.dispose();
    if (this.renderer) {
      this.renderer.dispose();
      this.renderer.forceContextLoss();
    }
    delete this.el.fwbProject;
    delete this.el.fwbDragStats;
    delete this.el.fwbHandles;
  }
}

// ---------------------------------------------------------------------------------------
// anywidget entry points. The store is created once per widget model in initialize();
// render() receives a per-view proxy of the same model, so the store is found by the
// model's unique _uid (set by Python).

const STORES = new Map();

function storeFor(model) {
  const uid = model.get("_uid");
  let s = STORES.get(uid);
  if (!s) {
    s = new Store(model);
    STORES.set(uid, s);
  }
  return s;
}

export default {
  initialize({ model }) {
    const store = storeFor(model);
    store.model = model;
    store.loadFull();
    const onFull = () => store.loadFull();
    const onMsg = (content, buffers) => {
      if (!content) return;
      if (content.type === "patch") {
        store.applyPatch(content, buffers || []);
        // The patch of a handle move doubles as its acknowledgement (see onAck).
        if (content.seq != null) for (const v of store.views) v.onAck(content);
      }
      else if (content.type === "handle_ack") for (const v of store.views) v.onAck(content);
      else if (content.type === "handle_cancel") for (const v of store.views) v.cancelDrag();
    };
    model.on("change:_version", onFull);
    model.on("change:_topology", onFull);
    model.on("msg:custom", onMsg);
    return () => {
      model.off("change:_version", onFull);
      model.off("change:_topology", onFull);
      model.off("msg:custom", onMsg);
      STORES.delete(model.get("_uid"));
    };
  },

  render({ model, el }) {
    const store = storeFor(model);
    if (!store.positions) store.loadFull();
    const view = new View(store, model, el);
    store.views.add(view);
    const handlers = {
      "change:wireframe": () => { view.updateWireframe(); view.requestRender(); },
      "change:_vertex_colors": () => { view.updateColors(); view.requestRender(); },
      "change:component_visible": () => { view.updateIndex(); view.requestRender(); },
      "change:_handles": () => { view.refreshHandleCache(); view.requestRender(); },
      "change:_handle_mirror": () => { view.refreshHandleCache(); view.requestRender(); },
      "change:selected_handle": () => { view.handlesDirty = true; view.requestRender(); },
      "change:symmetric": () => { view.handlesDirty = true; view.requestRender(); },
      "change:tool": () => view.updateTool(),
      "change:_probe_ids": () => view.writeProbe(),
      "change:_error": () => view.updateError(),
      "change:height": () => view.resize(),
    };
    for (const [ev, fn] of Object.entries(handlers)) model.on(ev, fn);
    return () => {
      for (const [ev, fn] of Object.entries(handlers)) model.off(ev, fn);
      store.views.delete(view);
      view.dispose();
    };
  },
};
