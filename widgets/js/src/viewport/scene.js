// One view of a viewport widget: renderer, scene, camera, controls, render loop, test hooks.
// Its markers (./markers.js), picking (./picking.js) and pointer input (./pointer_input.js,
// the tools of ./tools.js)
// live in their own modules; the geometry comes from the widget model's Store (./sync.js).
//
// Test hooks (attributes of the root element): data-frame / data-version / data-frame-time
// after each render with new geometry, data-render-count, data-ready, data-markers (marker
// page coordinates), data-probe (_probe_ids' page coordinates), data-tool, data-dragging,
// data-stroking, data-hover; el.fwbProject(ids), el.fwbMarkers(), el.fwbBrush(),
// el.fwbDragStats, el.fwbStrokeStats.
import * as THREE from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
import { isPlaying, onPlayback } from "../shared/playback.js";
import { cameraLinkMethods } from "./camera_link.js";
import { gpuViewMethods } from "./gpu_view.js";
import { markerMethods } from "./markers.js";
import { pickingMethods } from "./picking.js";
import { pointerInputMethods } from "./pointer_input.js";
import {
  DRAFT_PIXEL_RATIO, TINT_STRENGTH, TINT_COLOR, SKIN,
  colorForComponent, computeNormals, softwareWebGL, srgbToLinear, typed,
} from "./util.js";

export class View {
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
    this.tintDirty = null; // null | "full" | array of Uint32Array ids with new weights
    this.renderedTintVersion = -1;
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
    // Draft resolution while a timeline of this face model plays (software WebGL only).
    this.offPlayback = onPlayback(() => {
      this.setDraft(isPlaying(this.model.get("_scene")) && softwareWebGL());
    });
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
    this.initGpu(); // GPU evaluation of the rig (./gpu_view.js), or the note why not
    this.markerMesh = null;
    this.markersDirty = true;
    this.refreshMarkerCache();

    const controls = new OrbitControls(camera, renderer.domElement);
    controls.enableDamping = false; // render on demand only: no animation loop
    // userCamera: the person has orbited, zoomed or panned; from then on the camera is
    // theirs (a resize no longer re-frames the face, see resize()).
    this.userCamera = false;
    this.controlsActive = false;
    controls.addEventListener("start", () => { this.controlsActive = true; });
    controls.addEventListener("end", () => { this.controlsActive = false; });
    controls.addEventListener("change", () => {
      if (this.controlsActive) {
        this.userCamera = true;
        this.broadcastCamera(); // views in the same camera_group follow (./camera_link.js)
      }
      this.requestRender(false);
    });
    this.controls = controls;
    this.joinCameraGroup();
    this.onCameraGroup = () => this.joinCameraGroup();
    this.model.on("change:camera_group", this.onCameraGroup);

    this.awaitFrame = []; // acked messages waiting for the frame that shows them
    this.renderedVersion = -1;
    this.renderedTime = 0;
    this.initPointerInput(); // brush cursor, marker and brush tools, their listeners (./pointer_input.js)
    this.updateTool();

    this.resizeObserver = new ResizeObserver(() => this.resize());
    this.resizeObserver.observe(el);

    // Test hook: screen (client) coordinates of vertex ids, [[x, y, inFront], ...].
    el.fwbProject = (ids) => this.project(ids);
    el.fwbMarkers = () => this.markerScreenPositions();
    // Test hook: the marker a press at page (x, y) would grab, or -1 (occluded, or none there).
    el.fwbPickMarker = (x, y) => this.pickMarker(x, y, true);
    // Test hook: the brush cursor's centre in page coordinates, or null when hidden.
    el.fwbBrush = () => this.tools.stroke.brushScreenPosition();
    // Test hook: the positions the GPU evaluated (read back), or null when not on the GPU.
    el.fwbGpuPositions = () => this.gpuPositions();

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
    const topo = this.seenTopology !== s.topologyVersion;
    if (topo) {
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
    }
    if (this.gpuFrame()) { // positions and normals evaluated on the GPU
      this.seenPositions = s.positionsVersion;
      if (!this.framed) { g.computeBoundingSphere(); this.frameCamera(); }
      this.updateMarkers();
      return true;
    }
    if (!topo) {
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
    this.updateMarkers();
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
    this.indexVersion = (this.indexVersion || 0) + 1; // the draft follows (./gpu_draft.js)
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
      // the look of each component's part role (eyeball, teeth ...), recognised in the kernel
      // even when the name says nothing; the name is the fallback
      const materials = this.model.get("_component_materials") || [];
      const table = names.map((nm, i) => colorForComponent(materials[i] || nm).map(srgbToLinear));
      const skin = SKIN.map(srgbToLinear);
      const L = s.labels;
      for (let i = 0; i < n; i++) {
        const rgb = (L && table[L[i]]) || skin;
        C[3 * i] = rgb[0]; C[3 * i + 1] = rgb[1]; C[3 * i + 2] = rgb[2];
      }
    }
    this.applyTint(null);
  }

  // Colour attribute = base colours tinted by the tint weights (all, or only `ids`).
  applyTint(idLists) {
    const attr = this.geometry.getAttribute("color");
    const B = this.baseColors;
    if (!attr || !B || attr.array.length !== B.length) return;
    const C = attr.array;
    const W = this.store.tintW && this.store.tintW.length * 3 === B.length ? this.store.tintW : null;
    const T = this.tintColor || (this.tintColor = TINT_COLOR.map(srgbToLinear));
    const tint = (i) => {
      const a = W ? TINT_STRENGTH * Math.min(1, Math.max(0, W[i])) : 0;
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
    this.renderedTintVersion = this.store.tintVersion;
  }

  tintChanged(ids) {
    if (ids === null || this.tintDirty === "full") this.tintDirty = "full";
    else (this.tintDirty || (this.tintDirty = [])).push(ids);
    this.requestRender();
  }

  updateWireframe() {
    if (this.wire) this.wire.visible = !!this.model.get("wireframe") && this.lastDetail !== "draft";
  }

  updateError() {
    if (!this.banner) return;
    const msg = this.model.get("_error") || "";
    this.banner.textContent = msg;
    this.banner.style.display = msg ? "block" : "none";
    this.el.setAttribute("data-error", msg);
  }

  // ---- tools, gesture acks and their timing ------------------------------------------

  // Un-highlight the hovered marker (the pointer left the view, or the tool changed).
  clearHover() {
    if (this.hover < 0) return;
    this.hover = -1;
    this.el.setAttribute("data-hover", "-1");
    if (this.renderer && !this.drag) {
      this.renderer.domElement.style.cursor = this.toolKind() === "drag" ? "crosshair" : "";
    }
    this.markersDirty = true;
    this.requestRender();
  }

  // How the pointer works with the current tool: "drag" (markers), "stroke" (a brush)
  // or "" (orbit); the kernel sends each registered tool's kind (_tool_kinds).
  toolKind() {
    return (this.model.get("_tool_kinds") || {})[this.model.get("tool")] || "";
  }

  updateTool() {
    const kind = this.toolKind();
    const dragging = kind === "drag";
    this.el.setAttribute("data-tool", kind ? this.model.get("tool") : "orbit");
    if (!this.tools) return;
    if (!dragging) this.tools.drag.end(null);
    this.tools.drag.click = null;
    this.clearHover();
    if (kind !== "stroke") {
      this.tools.stroke.end(null);
      if (this.brushRing) { this.brushRing.visible = false; this.brushMirrorRing.visible = false; }
    }
    if (this.renderer) this.renderer.domElement.style.cursor = kind ? "crosshair" : "";
    this.markersDirty = true;
    this.requestRender();
  }

  // A gesture ack, or a geometry patch carrying a gesture message's seq.
  onAck(content) {
    for (const t of Object.values(this.tools || {})) t.client.onAck(content);
    // A dab that changed nothing still moved the brush cursor.
    if (this.stroke && !this.geometryDirty && !this.tintDirty) this.requestRender();
    // A move that changed no geometry still moved the marker.
    if (this.markersDirty && !this.geometryDirty) this.requestRender();
  }

  // Python ended the gesture of `kind` ("drag" | "stroke").
  onCancel(kind, content) {
    if (!this.tools) return;
    (kind === "drag" ? this.tools.drag : this.tools.stroke).client.onCancel(content);
  }

  // The timing of an acked message: reported once a render shows its update.
  onStat(st) {
    // The tint patch of a stroke message came before its ack (same channel, in order).
    st.tintVersion = this.store.tintVersion;
    if (this.statShown(st)) this.finishStat(st, this.renderedTime);
    else this.awaitFrame.push(st);
  }

  // Has a render shown this update (its geometry version and its tint version)?
  statShown(st) {
    return (
      this.renderedVersion >= st.version && !this.geometryDirty &&
      (st.tintVersion == null || this.renderedTintVersion >= st.tintVersion) && !this.tintDirty
    );
  }

  finishStat(st, frameTime) {
    // A move that changed nothing shows no new frame: no latency to report.
    st.frame = frameTime >= st.input ? frameTime : null;
    const list = st.kind === "stroke" ? this.strokeStats : this.dragStats;
    list.push(st);
    if (list.length > 4000) list.splice(0, 2000);
    this.el.setAttribute(
      st.kind === "stroke" ? "data-stroke-updates" : "data-drag-updates", String(list.length));
  }

  // ---- brush tool -----------------------------------------------------------------------


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
    this.frameDist = dist; // the zoom a linked camera shares is relative to it (./camera_link.js)
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
    } else if (this.markersDirty) {
      this.updateMarkers();
    }
    if (this.tintDirty && this.positionAttr) {
      const d = this.tintDirty;
      this.tintDirty = null;
      this.applyTint(d === "full" ? null : d);
      newGeometry = true; // new pixels: counts as a frame for the test hooks and latency
      this.el.setAttribute("data-tint-version", String(this.store.tintVersion));
    }
    if (this.featureGraph) this.featureGraph.beforeRender(); // feature-graph overlay
    this.renderer.render(this.scene, this.camera);
    if (newGeometry && this.gpuDrawn && this.gpuOn()) this.fenceFrame();
    // Benchmarks: wait until the GPU has drawn it (WebGL returns before SwiftShader draws)
    if (newGeometry && globalThis.fwbSyncFrames) this.renderer.getContext().readPixels(0, 0, 1, 1, 6408, 5121, new Uint8Array(4));
    this.renders += 1;
    const el = this.el;
    el.setAttribute("data-render-count", String(this.renders));
    if (newGeometry && this.lastFrameDraft) {
      // a draft (./gpu_draft.js): data-frame waits for the full mesh
      this.lastFrameDraft = false;
      el.setAttribute("data-draft-frame", String(this.draftFrames));
      el.setAttribute("data-draft-frame-time", String(performance.now()));
    } else if (newGeometry) {
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
    this.writeMarkerHook();
  }

  // ---- test hooks ---------------------------------------------------------------------

  project(ids) {
    this.cpuRows(ids); // GPU path: these rows evaluated on the CPU (./gpu_view.js)
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
    this.leaveCameraGroup();
    if (this.onCameraGroup) this.model.off("change:camera_group", this.onCameraGroup);
    this.disposePointerInput();
    if (this.resizeObserver) this.resizeObserver.disconnect();
    if (this.offPlayback) this.offPlayback();
    this.disposeGpu();
    if (this.controls) this.controls.dispose();
    if (this.markerMesh) this.markerMesh.geometry.dispose();
    if (this.geometry) this.geometry.dispose();
    if (this.material) this.material.dispose();
    if (this.wireMaterial) this.wireMaterial.dispose();
    if (this.renderer) {
      this.renderer.dispose();
      this.renderer.forceContextLoss();
    }
    delete this.el.fwbProject;
    delete this.el.fwbDragStats;
    delete this.el.fwbMarkers;
    delete this.el.fwbStrokeStats;
    delete this.el.fwbBrush;
    delete this.el.fwbGpuPositions;
    delete this.el.fwbPickMarker;
  }
}


Object.assign(View.prototype, markerMethods, pickingMethods, pointerInputMethods, cameraLinkMethods, gpuViewMethods);
