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
//   _neutral_bounds {min, max, radius}  the NEUTRAL mesh's box: the camera is framed on it
//                                       once (so the framing does not depend on the
//                                       expression shown when the view opened), and
//                                       the handle markers are sized by its radius
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
//
// Paint tool (tool == "paint", Pighin et al. 1998 §4.2 painterly blending), front end -> Python:
//   {type: "paint", phase: "start"|"move"|"end", vertices: [v, ...], seq}
//       a left press ON the face starts a stroke (off the face, or with Alt, the left
//       button orbits). Every pointer move raycasts the face; the nearest corner of the
//       hit triangle is queued when it lies a quarter brush radius from the last queued
//       point. Like handle moves, at most ONE message is in flight: the queue (at most
//       the 8 newest vertices) goes out when Python's {type: "paint_ack", seq} - or the
//       geometry patch carrying that seq - arrives. Release sends "end" (one undo step).
//   stroke_target   non-empty while Python sends strokes to a stroke handler instead of
//       the paint layers (e.g. the wrinkle eraser): a press paints even with no
//       paint_expression, and _paint_weights is the handler's overlay (its mask).
//   _paint_weights  bytes, float32 (n) or empty: the selected expression's weights,
//   msg:custom      {type: "paint_patch", version}, buffers [ids uint32, weights float32]
//       drawn as a magenta tint over the component colours (weight-map overlay).
//   brush_radius (model units along the surface) sets the size of the brush cursor: a
//   ring lying on the surface under the pointer (and at the x-mirror with brush_mirror).
// Feature-graph overlay (pose-space wrinkles, Bickel et al. 2008 §5.1), Python -> front end:
//   _feature_edges   bytes, uint32 (F*2): vertex ids of the edges between handles
//   _feature_strain  bytes, float32 (F): relative stretch of each edge
//   feature_graph (bool, draw it), strain_range (|strain| drawn in full colour)
//   Fat line segments over the surface, blue (compressed) - grey (rest) - red (stretched),
//   end points following the drawn geometry; a colour-scale legend in the corner. The
//   lines are depth-tested against the face (hidden behind the head seen from the back),
//   pulled toward the camera along the view ray so chords lying on the skin stay visible.
// All views of one widget model share one geometry store (state lives in the model,
// not in the view), so a second display of the same widget shows the same frame.

import * as THREE from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
// feature-graph overlay (section "Feature-graph overlay" below)
import { LineSegments2 } from "three/examples/jsm/lines/LineSegments2.js";
import { LineSegmentsGeometry } from "three/examples/jsm/lines/LineSegmentsGeometry.js";
import { LineMaterial } from "three/examples/jsm/lines/LineMaterial.js";

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

// Weight-map overlay: colour = mix(component colour, PAINT_TINT, PAINT_STRENGTH * weight).
const PAINT_TINT = [0.95, 0.1, 0.85]; // sRGB magenta
const PAINT_STRENGTH = 0.85;
const BRUSH_COLOR = 0xfff27a;
const MAX_QUEUE = 8; // most dab vertices per paint message

function colorForComponent(name) {
  for (const [re, rgb] of COMPONENT_COLORS) if (re.test(name || "")) return rgb;
  return SKIN;
}

function srgbToLinear(c) {
  return c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4);
}

// ---------------------------------------------------------------------------------------
// Software WebGL (SwiftShader, llvmpipe: a machine without a GPU) is fill-rate bound:
// measured on the 2-core reference machine (benchmarks/bench_playback.py), MSAA doubles
// the time the GPU process needs per frame and every frame is read back for software
// compositing. There the view draws without MSAA and, while a timeline plays, at half
// resolution ("draft"); the full-resolution frame is drawn again as soon as playback stops.
let SOFTWARE_WEBGL = null;
function softwareWebGL() {
  if (SOFTWARE_WEBGL !== null) return SOFTWARE_WEBGL;
  SOFTWARE_WEBGL = false;
  try {
    const gl = document.createElement("canvas").getContext("webgl2");
    if (gl) {
      const info = gl.getExtension("WEBGL_debug_renderer_info");
      const name = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
      SOFTWARE_WEBGL = /swiftshader|llvmpipe|softpipe|software/i.test(name);
      const lose = gl.getExtension("WEBGL_lose_context");
      if (lose) lose.loseContext();
    }
  } catch (err) { /* no WebGL2: the renderer below reports it */ }
  return SOFTWARE_WEBGL;
}
const DRAFT_PIXEL_RATIO = 0.5; // of the device pixel ratio, while a timeline plays
// timeline.js dispatches this window event when playback starts or stops
const PLAYBACK_EVENT = "fwb-playback";

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
    this.paintW = null; // Float32Array n: painted weights of the selected expression, or null
    this.paintVersion = -1;
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
    this.paintDirty = null; // null | "full" | array of Uint32Array ids with new weights
    this.renderedPaintVersion = -1;
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
        antialias: !softwareWebGL(), // see softwareWebGL()
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
    el.setAttribute("data-software-webgl", softwareWebGL() ? "1" : "0");
    el.setAttribute("data-draft", "0");
    // Draft resolution while any timeline of the page plays (software WebGL only).
    this.playingTimelines = new Set();
    this.onPlayback = (ev) => {
      const { id, playing } = ev.detail || {};
      if (playing) this.playingTimelines.add(id);
      else this.playingTimelines.delete(id);
      this.setDraft(this.playingTimelines.size > 0 && softwareWebGL());
    };
    window.addEventListener(PLAYBACK_EVENT, this.onPlayback);
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

    const controls = new OrbitControls(camera, renderer.domElement);
    controls.enableDamping = false; // render on demand only: no animation loop
    // userCamera: the person has orbited, zoomed or panned; from then on the camera is
    // theirs (a resize no longer re-frames the face, see resize()).
    this.userCamera = false;
    this.controlsActive = false;
    controls.addEventListener("start", () => { this.controlsActive = true; });
    controls.addEventListener("end", () => { this.controlsActive = false; });
    controls.addEventListener("change", () => {
      if (this.controlsActive) this.userCamera = true;
      this.requestRender(false);
    });
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
    // Same for paint messages: {seq, input, send, ack, frame, kernel, dabs}.
    this.paintStats = [];
    el.fwbPaintStats = this.paintStats;
    this.stroke = null; // the paint stroke in progress
    this.listeners = {
      pointerdown: (e) => this.onPointerDown(e),
      pointermove: (e) => this.onPointerMove(e),
      pointerup: (e) => this.onPointerUp(e),
      pointercancel: (e) => this.onPointerUp(e),
    };
    for (const [ev, fn] of Object.entries(this.listeners)) el.addEventListener(ev, fn, true);
    this.onLostCapture = (e) => {
      if (this.drag && e.pointerId === this.drag.pointerId) this.endDrag(null);
      if (this.stroke && e.pointerId === this.stroke.pointerId) this.endStroke(null);
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
        // the last dragged one (selected_handle, cleared for every view).
        this.clearHover();
        if (this.model.get("selected_handle") >= 0) {
          this.model.set("selected_handle", -1);
          this.model.save_changes();
          this.handlesDirty = true;
          this.requestRender();
        }
      }
    };
    renderer.domElement.addEventListener("pointerleave", this.onLeave);
    renderer.domElement.addEventListener("lostpointercapture", this.onLostCapture);
    this.updateTool();

    this.resizeObserver = new ResizeObserver(() => this.resize());
    this.resizeObserver.observe(el);

    // Test hook: screen (client) coordinates of vertex ids, [[x, y, inFront], ...].
    el.fwbProject = (ids) => this.project(ids);
    el.fwbHandles = () => this.handleScreenPositions();
    // Test hook: the brush cursor's centre in page coordinates, or null when hidden.
    el.fwbBrush = () => this.brushScreenPosition();

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
    if (!this.baseColors || this.baseColors.length !== n * 3) this.baseColors = new Float32Array(n * 3);
    const C = this.baseColors;
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
    this.applyPaint(null);
  }

  // Colour attribute = base colours tinted by the painted weights (all, or only `ids`).
  applyPaint(idLists) {
    const attr = this.geometry.getAttribute("color");
    const B = this.baseColors;
    if (!attr || !B || attr.array.length !== B.length) return;
    const C = attr.array;
    const W = this.store.paintW && this.store.paintW.length * 3 === B.length ? this.store.paintW : null;
    const T = this.paintTint || (this.paintTint = PAINT_TINT.map(srgbToLinear));
    const tint = (i) => {
      const a = W ? PAINT_STRENGTH * Math.min(1, Math.max(0, W[i])) : 0;
      const j = 3 * i;
      C[j] = B[j] + a * (T[0] - B[j]);
      C[j + 1] = B[j + 1] + a * (T[1] - B[j + 1]);
      C[j + 2] = B[j + 2] + a * (T[2] - B[j + 2]);
    };
    if (idLists && W) {
      for (const ids of idLists) for (let k = 0; k < ids.length; k++) if (ids[k] < W.length) tint(ids[k]);
    } else {
      const n = B.length / 3;
      for (let i = 0; i < n; i++) tint(i);
    }
    attr.needsUpdate = true;
    this.renderedPaintVersion = this.store.paintVersion;
  }

  paintChanged(ids) {
    if (ids === null || this.paintDirty === "full") this.paintDirty = "full";
    else (this.paintDirty || (this.paintDirty = [])).push(ids);
    this.requestRender();
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

  // The last dragged marker, highlighted while the sculpt tool is on (-1: none).
  selectedHandle() {
    if (this.model.get("tool") !== "sculpt") return -1;
    const sel = this.model.get("selected_handle");
    return sel >= 0 && sel < this.handleIds.length ? sel : -1;
  }

  // Which marker gets the highlight: the dragged one, else the hovered, else the selected.
  activeHandle() {
    if (this.drag) return this.drag.index;
    if (this.hover >= 0) return this.hover;
    return this.selectedHandle();
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
    const selected = this.selectedHandle();
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

  // Un-highlight the hovered marker (the pointer left the view, or the tool changed).
  clearHover() {
    if (this.hover < 0) return;
    this.hover = -1;
    this.el.setAttribute("data-hover", "-1");
    if (this.renderer && !this.drag) {
      this.renderer.domElement.style.cursor = this.model.get("tool") === "sculpt" ? "crosshair" : "";
    }
    this.handlesDirty = true;
    this.requestRender();
  }

  updateTool() {
    const tool = this.model.get("tool");
    const sculpt = tool === "sculpt";
    this.el.setAttribute("data-tool", tool === "sculpt" || tool === "paint" ? tool : "orbit");
    if (!sculpt && this.drag) this.endDrag(null);
    this.click = null;
    this.clearHover();
    if (tool !== "paint") {
      if (this.stroke) this.endStroke(null);
      if (this.brushRing) { this.brushRing.visible = false; this.brushMirrorRing.visible = false; }
    }
    if (this.renderer) this.renderer.domElement.style.cursor = sculpt || tool === "paint" ? "crosshair" : "";
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

  // Nearest hit of the pointer ray with the drawn (visible) triangles, in the shape of a
  // three.js intersection ({distance, point, face: {a, b, c, normal}}), or null.
  // A flat Moller-Trumbore loop over the typed arrays instead of Raycaster.intersectObject:
  // three.js's generic path (bounding sphere of the deformed mesh + per-triangle Vector3
  // work) took 7 ms at 25k and 22 ms at 100k vertices per pointer event while painting;
  // this loop is several times faster and needs no bounds (the mesh has no transform).
  raycastSurface(clientX, clientY) {
    if (!this.positionAttr || !this.geometry.index) return null;
    this.raycaster.setFromCamera(this.ndc(clientX, clientY), this.camera);
    const ray = this.raycaster.ray;
    const ox = ray.origin.x, oy = ray.origin.y, oz = ray.origin.z;
    const dx = ray.direction.x, dy = ray.direction.y, dz = ray.direction.z;
    const P = this.positionAttr.array;
    const F = this.geometry.index.array;
    const near = this.camera.near;
    let best = Infinity;
    let bestF = -1;
    for (let f = 0; f < F.length; f += 3) {
      const a = 3 * F[f], b = 3 * F[f + 1], c = 3 * F[f + 2];
      const ax = P[a], ay = P[a + 1], az = P[a + 2];
      const e1x = P[b] - ax, e1y = P[b + 1] - ay, e1z = P[b + 2] - az;
      const e2x = P[c] - ax, e2y = P[c + 1] - ay, e2z = P[c + 2] - az;
      const px = dy * e2z - dz * e2y, py = dz * e2x - dx * e2z, pz = dx * e2y - dy * e2x;
      const det = e1x * px + e1y * py + e1z * pz;
      if (det > -1e-12 && det < 1e-12) continue; // parallel (double-sided: no culling)
      const inv = 1 / det;
      const tx = ox - ax, ty = oy - ay, tz = oz - az;
      const u = (tx * px + ty * py + tz * pz) * inv;
      if (u < 0 || u > 1) continue;
      const qx = ty * e1z - tz * e1y, qy = tz * e1x - tx * e1z, qz = tx * e1y - ty * e1x;
      const v = (dx * qx + dy * qy + dz * qz) * inv;
      if (v < 0 || u + v > 1) continue;
      const t = (e2x * qx + e2y * qy + e2z * qz) * inv;
      if (t > near && t < best) { best = t; bestF = f; }
    }
    if (bestF < 0) return null;
    const ia = F[bestF], ib = F[bestF + 1], ic = F[bestF + 2];
    const va = new THREE.Vector3(P[3 * ia], P[3 * ia + 1], P[3 * ia + 2]);
    const vb = new THREE.Vector3(P[3 * ib], P[3 * ib + 1], P[3 * ib + 2]);
    const vc = new THREE.Vector3(P[3 * ic], P[3 * ic + 1], P[3 * ic + 2]);
    const normal = new THREE.Vector3();
    THREE.Triangle.getNormal(va, vb, vc, normal);
    return {
      distance: best,
      point: ray.at(best, new THREE.Vector3()),
      face: { a: ia, b: ib, c: ic, normal },
    };
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
    if (this.renderer && this.model.get("tool") === "paint") { this.onPaintDown(e); return; }
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
    if (this.stroke || (this.renderer && this.model.get("tool") === "paint")) {
      this.onPaintMove(e);
      return;
    }
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
    this.pointerInside = true;
    if (this.hoverPending) return;
    this.hoverPending = true;
    requestAnimationFrame(() => {
      this.hoverPending = false;
      // (a pick queued just before the pointer left must not light a marker again)
      if (!this.renderer || this.drag || !this.pointerInside) return;
      if (this.model.get("tool") !== "sculpt") return;
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
    if (this.stroke) {
      if (e.pointerId !== this.stroke.pointerId) return;
      e.stopPropagation(); e.preventDefault();
      this.endStroke(e);
      return;
    }
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
      // The overlay patch of a paint message came before its ack (same channel, in order).
      st.paintVersion = this.store.paintVersion;
      // The geometry of this move arrived before its ack (same channel, in order).
      if (this.statShown(st)) {
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
    const s = this.stroke;
    if (s && s.inFlight === content.seq) {
      s.inFlight = 0;
      this.flushStroke();
    }
    // A dab that changed nothing still moved the brush cursor.
    if (this.stroke && !this.geometryDirty && !this.paintDirty) this.requestRender();
    // A move that changed no geometry still moved the marker.
    if (this.handlesDirty && !this.geometryDirty) this.requestRender();
  }

  // Has a render shown this update (its geometry version and its paint overlay version)?
  statShown(st) {
    return (
      this.renderedVersion >= st.version && !this.geometryDirty &&
      (st.paintVersion == null || this.renderedPaintVersion >= st.paintVersion) && !this.paintDirty
    );
  }

  finishStat(st, frameTime) {
    // A move that changed nothing shows no new frame: no latency to report.
    st.frame = frameTime >= st.input ? frameTime : null;
    const list = st.kind === "paint" ? this.paintStats : this.dragStats;
    list.push(st);
    if (list.length > 4000) list.splice(0, 2000);
    this.el.setAttribute(
      st.kind === "paint" ? "data-paint-updates" : "data-drag-updates", String(list.length));
  }

  // ---- paint tool -----------------------------------------------------------------------

  // Ray hit on the face -> {vertex, point, normal}, or null.
  paintHit(clientX, clientY) {
    const hit = this.raycastSurface(clientX, clientY);
    if (!hit || !hit.face) return null;
    const A = this.positionAttr.array;
    let best = -1;
    let bestD = Infinity;
    for (const i of [hit.face.a, hit.face.b, hit.face.c]) {
      const d = Math.hypot(A[3 * i] - hit.point.x, A[3 * i + 1] - hit.point.y, A[3 * i + 2] - hit.point.z);
      if (d < bestD) { bestD = d; best = i; }
    }
    const normal = hit.face.normal.clone();
    // Face the camera (the material is double-sided; the back of a lip can be hit).
    if (normal.dot(this.raycaster.ray.direction) > 0) normal.negate();
    return { vertex: best, point: hit.point.clone(), normal };
  }

  placeBrush(hit) {
    const r = Math.max(1e-6, Number(this.model.get("brush_radius")) || 0);
    const z = new THREE.Vector3(0, 0, 1);
    const place = (ring, point, normal) => {
      ring.position.copy(point).addScaledVector(normal, r * 0.02);
      ring.quaternion.setFromUnitVectors(z, normal);
      ring.scale.set(r, r, r);
      ring.visible = true;
    };
    if (!hit) {
      this.brushRing.visible = false;
      this.brushMirrorRing.visible = false;
      return;
    }
    this.brushHit = hit;
    place(this.brushRing, hit.point, hit.normal);
    if (this.model.get("brush_mirror")) {
      const mp = hit.point.clone(); mp.x = -mp.x;
      const mn = hit.normal.clone(); mn.x = -mn.x;
      place(this.brushMirrorRing, mp, mn);
    } else {
      this.brushMirrorRing.visible = false;
    }
  }

  brushSettingsChanged() {
    if (this.brushRing && this.brushRing.visible && this.brushHit) this.placeBrush(this.brushHit);
    this.requestRender();
  }

  brushScreenPosition() {
    if (!this.brushRing || !this.brushRing.visible || !this.renderer) return null;
    const v = this.brushRing.position.clone().project(this.camera);
    const rect = this.renderer.domElement.getBoundingClientRect();
    return [rect.left + ((v.x + 1) / 2) * rect.width, rect.top + ((1 - v.y) / 2) * rect.height];
  }

  onPaintDown(e) {
    if (this.stroke || e.button !== 0 || e.altKey || e.ctrlKey || e.metaKey) return;
    // Nothing to paint (no expression picked, no stroke handler in Python): the press orbits.
    if (!this.model.get("paint_expression") && !this.model.get("stroke_target")) return;
    const hit = this.paintHit(e.clientX, e.clientY);
    if (!hit) return; // off the face: OrbitControls gets it
    e.stopPropagation(); e.preventDefault();
    this.stroke = {
      pointerId: e.pointerId,
      inFlight: 0,
      sentAt: 0,
      queue: [hit.vertex],
      last: hit.point.clone(),
      inputTime: e.timeStamp,
      started: false,
    };
    this.controls.enabled = false;
    try { this.renderer.domElement.setPointerCapture(e.pointerId); } catch (err) { /* synthetic */ }
    this.el.setAttribute("data-painting", "1");
    this.placeBrush(hit);
    this.sendPaint("start");
    this.requestRender();
  }

  onPaintMove(e) {
    const s = this.stroke;
    if (s) {
      if (e.pointerId !== s.pointerId) return;
      e.stopPropagation(); e.preventDefault();
      const hit = this.paintHit(e.clientX, e.clientY);
      if (!hit) return; // slid off the face: no dab, the stroke goes on
      this.placeBrush(hit);
      const r = Number(this.model.get("brush_radius")) || 0;
      if (hit.point.distanceTo(s.last) >= 0.25 * r) {
        s.queue.push(hit.vertex);
        if (s.queue.length > MAX_QUEUE) s.queue.splice(0, s.queue.length - MAX_QUEUE);
        s.last.copy(hit.point);
        s.inputTime = e.timeStamp;
      }
      // No render here: the dab's overlay/geometry update redraws the cursor too.
      this.flushStroke();
      return;
    }
    if (e.buttons !== 0) return; // orbiting
    this.hoverAt = [e.clientX, e.clientY];
    if (this.hoverPending) return;
    this.hoverPending = true;
    requestAnimationFrame(() => {
      this.hoverPending = false;
      if (!this.renderer || this.stroke || this.model.get("tool") !== "paint") return;
      this.placeBrush(this.paintHit(this.hoverAt[0], this.hoverAt[1]));
      this.requestRender();
    });
  }

  sendPaint(phase) {
    const s = this.stroke;
    this.seq += 1;
    const vertices = s.queue;
    s.queue = [];
    this.model.send({ type: "paint", phase, vertices, seq: this.seq });
    if (phase !== "end") {
      s.inFlight = this.seq;
      s.sentAt = performance.now();
      if (vertices.length) {
        this.pendingStats.set(this.seq, {
          kind: "paint", seq: this.seq, input: s.inputTime, send: s.sentAt, dabs: vertices.length,
        });
      }
    }
  }

  // Send the queued dabs unless a message is still in flight (or lost for 2 s).
  flushStroke() {
    const s = this.stroke;
    if (!s || !s.queue.length) return;
    if (s.inFlight && performance.now() - s.sentAt < 2000) return;
    this.sendPaint("move");
  }

  endStroke(e) {
    const s = this.stroke;
    if (!s) return;
    if (e && e.type === "pointerup") {
      const hit = this.paintHit(e.clientX, e.clientY);
      const r = Number(this.model.get("brush_radius")) || 0;
      if (hit && hit.point.distanceTo(s.last) >= 0.25 * r) s.queue.push(hit.vertex);
    }
    this.sendPaint("end");
    this.stroke = null;
    this.controls.enabled = true;
    try { this.renderer.domElement.releasePointerCapture(s.pointerId); } catch (err) { /* gone */ }
    this.el.setAttribute("data-painting", "0");
    this.requestRender();
  }

  cancelStroke() {
    if (!this.stroke) return;
    this.stroke = null;
    this.controls.enabled = true;
    this.el.setAttribute("data-painting", "0");
    this.requestRender();
  }

  // The box the camera frames: the neutral mesh's (Python's _neutral_bounds), so a view
  // opened on a posed face (jaw open, a recovered session) frames it like a fresh one;
  // the drawn geometry only when the bounds are missing.
  frameBox() {
    const nb = this.model.get("_neutral_bounds") || {};
    const lo = nb.min, hi = nb.max;
    if (Array.isArray(lo) && Array.isArray(hi) && lo.length === 3 && hi.length === 3 &&
        lo.concat(hi).every((x) => isFinite(x)) && hi.some((x, i) => x > lo[i])) {
      return new THREE.Box3(new THREE.Vector3(...lo), new THREE.Vector3(...hi));
    }
    const sphere = this.geometry.boundingSphere;
    if (!sphere || !isFinite(sphere.radius) || sphere.radius <= 0) return null;
    return new THREE.Box3().setFromBufferAttribute(this.geometry.getAttribute("position"));
  }

  frameCamera() {
    const box = this.frameBox();
    if (!box) return;
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
    // Until the person moves the camera the framing follows the canvas size: the first
    // geometry usually arrives before the notebook has laid the view out at its width
    // (it was framed for the 320 px minimum), and a fresh app and one opened later must
    // look the same.
    if (this.framed && !this.userCamera) this.frameCamera();
    this.requestRender(false);
  }

  setDraft(on) {
    if (!this.renderer || on === !!this.draft) return;
    this.draft = on;
    const dpr = window.devicePixelRatio || 1;
    this.renderer.setPixelRatio(on ? dpr * DRAFT_PIXEL_RATIO : dpr);
    this.el.setAttribute("data-draft", on ? "1" : "0");
    this.resize(); // re-applies the size at the new ratio and redraws
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
    if (this.paintDirty && this.positionAttr) {
      const d = this.paintDirty;
      this.paintDirty = null;
      this.applyPaint(d === "full" ? null : d);
      newGeometry = true; // new pixels: counts as a frame for the test hooks and latency
      this.el.setAttribute("data-paint-version", String(this.store.paintVersion));
    }
    if (this.featureGraph) this.featureGraph.beforeRender(); // feature-graph overlay
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
          if (this.statShown(st)) this.finishStat(st, t1); else keep.push(st);
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
    if (this.stroke) { try { this.endStroke(null); } catch (err) { /* closing */ } }
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
    if (this.resizeObserver) this.resizeObserver.disconnect();
    if (this.onPlayback) window.removeEventListener(PLAYBACK_EVENT, this.onPlayback);
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
    delete this.el.fwbPaintStats;
    delete this.el.fwbBrush;
  }
}

// =======================================================================================
// Feature-graph overlay (pose-space wrinkles, Bickel et al. 2008 §5.1).
// Self-contained: a View gets one in render() below and calls beforeRender() once per
// render; nothing else in this file depends on it. Python side: the "feature graph
// overlay" section of widgets/viewport.py, fed by widgets/wrinkle_panel.py.

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

class FeatureGraphOverlay {
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
    store.loadPaintFull();
    const onFull = () => store.loadFull();
    const onPaintFull = () => store.loadPaintFull();
    const onMsg = (content, buffers) => {
      if (!content) return;
      if (content.type === "patch") {
        store.applyPatch(content, buffers || []);
        // The patch of a handle move doubles as its acknowledgement (see onAck).
        if (content.seq != null) for (const v of store.views) v.onAck(content);
      }
      else if (content.type === "handle_ack") for (const v of store.views) v.onAck(content);
      else if (content.type === "handle_cancel") for (const v of store.views) v.cancelDrag();
      else if (content.type === "paint_patch") store.applyPaintPatch(content, buffers || []);
      else if (content.type === "paint_ack") for (const v of store.views) v.onAck(content);
      else if (content.type === "paint_cancel") for (const v of store.views) v.cancelStroke();
    };
    model.on("change:_version", onFull);
    model.on("change:_topology", onFull);
    model.on("change:_paint_version", onPaintFull);
    model.on("msg:custom", onMsg);
    return () => {
      model.off("change:_version", onFull);
      model.off("change:_topology", onFull);
      model.off("change:_paint_version", onPaintFull);
      model.off("msg:custom", onMsg);
      STORES.delete(model.get("_uid"));
    };
  },

  render({ model, el }) {
    const store = storeFor(model);
    if (!store.positions) store.loadFull();
    store.loadPaintFull();
    const view = new View(store, model, el);
    store.views.add(view);
    const featureGraph = new FeatureGraphOverlay(view, model); // feature-graph overlay
    view.featureGraph = featureGraph;
    const handlers = {
      "change:wireframe": () => { view.updateWireframe(); view.requestRender(); },
      "change:_vertex_colors": () => { view.updateColors(); view.requestRender(); },
      "change:component_visible": () => { view.updateIndex(); view.requestRender(); },
      "change:_handles": () => { view.refreshHandleCache(); view.requestRender(); },
      "change:_handle_mirror": () => { view.refreshHandleCache(); view.requestRender(); },
      "change:selected_handle": () => { view.handlesDirty = true; view.requestRender(); },
      "change:symmetric": () => { view.handlesDirty = true; view.requestRender(); },
      "change:tool": () => view.updateTool(),
      "change:brush_radius": () => view.brushSettingsChanged(),
      "change:brush_mirror": () => view.brushSettingsChanged(),
      "change:_probe_ids": () => view.writeProbe(),
      "change:_error": () => view.updateError(),
      "change:height": () => view.resize(),
    };
    for (const [ev, fn] of Object.entries(handlers)) model.on(ev, fn);
    return () => {
      for (const [ev, fn] of Object.entries(handlers)) model.off(ev, fn);
      store.views.delete(view);
      featureGraph.dispose();
      view.dispose();
    };
  },
};
