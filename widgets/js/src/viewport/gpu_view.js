// The GPU path of a View (methods mixed into View, see ./scene.js): evaluate the rig with
// ./gpu_morph.js when Python sends parameters (_gpu_mode "gpu"), read positions back when
// the CPU needs them (picking, markers, probes, the feature graph), and show a note when
// the view falls back to vertices streamed from the kernel.
import { draftViewMethods } from "./gpu_draft.js";
import { GpuMorph, gpuUnsupported, patchMaterial } from "./gpu_morph.js";
import { typed } from "./util.js";

export const gpuViewMethods = {
  ...draftViewMethods,

  initGpu() {
    this.gpu = null;
    this.gpuReason = "";
    this.cpuSeen = -1; // store.positionsVersion the CPU positions show
    this.gpuDrawn = false;
    const note = document.createElement("div");
    Object.assign(note.style, {
      position: "absolute", left: "6px", bottom: "6px", padding: "2px 6px", maxWidth: "80%",
      background: "rgba(20,24,30,0.72)", color: "#e8c468", font: "11px sans-serif",
      borderRadius: "3px", display: "none", pointerEvents: "none",
    });
    note.className = "fwb-gpu-note";
    this.el.appendChild(note);
    this.gpuNote = note;
    this.gpuReason = gpuUnsupported(this.renderer, this.store);
    if (!this.gpuReason) {
      try {
        this.gpu = new GpuMorph(this.renderer);
        patchMaterial(this.material, this.gpu.drawUniforms);
        patchMaterial(this.wireMaterial, this.gpu.drawUniforms);
      } catch (err) {
        this.gpu = null;
        this.gpuReason = `GPU set-up failed: ${err}`;
      }
    }
    this.onGpuTrait = () => { this.reportGpu(); this.updateGpuNote(); this.geometryChanged(); };
    this.model.on("change:gpu", this.onGpuTrait);
    this.model.on("change:_gpu_mode", this.onGpuTrait);
    this.reportGpu();
    this.updateGpuNote();
    this.installGpuHooks();
    this.initDraft();
  },

  // Benchmark and test hooks on the element (installed once).
  installGpuHooks() {
    // Benchmark hook: ms per GPU evaluation (both passes) and per draw, synchronised by a
    // one-pixel readback.
    this.el.fwbGpuTime = (n = 10) => {
      if (!this.gpuOn()) return null;
      const px = new Float32Array(4);
      const sync = () => this.renderer.readRenderTargetPixels(this.gpu.nrmRT, 0, 0, 1, 1, px);
      sync();
      let t0 = performance.now();
      for (let i = 0; i < n; i++) { this.gpu.evaluate(); sync(); }
      const evalMs = (performance.now() - t0) / n;
      const gl = this.renderer.getContext();
      const one = new Uint8Array(4);
      t0 = performance.now();
      for (let i = 0; i < n; i++) {
        this.renderer.render(this.scene, this.camera);
        gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, one);
      }
      const drawMs = (performance.now() - t0) / n;
      this.gpu.drawUniforms.fwbGpu.value = false;
      t0 = performance.now();
      for (let i = 0; i < n; i++) {
        this.renderer.render(this.scene, this.camera);
        gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, one);
      }
      const cpuDrawMs = (performance.now() - t0) / n;
      this.gpu.drawUniforms.fwbGpu.value = true;
      const r = this.renderer;
      t0 = performance.now();
      for (let i = 0; i < n; i++) {
        r.setRenderTarget(this.gpu.posRT); r.render(this.gpu.evalScene, this.gpu.quadCamera);
        r.setRenderTarget(null); sync();
      }
      const morphMs = (performance.now() - t0) / n;
      t0 = performance.now();
      for (let i = 0; i < n; i++) {
        r.setRenderTarget(this.gpu.nrmRT); r.render(this.gpu.normalScene, this.gpu.quadCamera);
        r.setRenderTarget(null); sync();
      }
      const normalMs = (performance.now() - t0) / n;
      return { evalMs, drawMs, cpuDrawMs, morphMs, normalMs, canvas: [r.domElement.width, r.domElement.height] };
    };
    this.el.fwbGpuNormals = () => this.gpuNormals();
    // Test hook: what the GPU path evaluates now.
    this.el.fwbGpuState = () => ({
      on: this.gpuOn(), reason: this.gpuReason, params: Array.from(this.store.gpuParams || []),
      evaluations: this.gpu ? this.gpu.evaluations : 0, playing: !!this.store.clipPlay,
      textureBytes: this.gpu ? this.gpu.textureBytes() : 0, missing: this.store.gpuMissing(),
    });
  },

  // Tell Python whether this view can evaluate the rig: "gpu_ready" switches it from
  // streaming vertex rows to parameters; "gpu_unavailable" keeps every view of the widget
  // (or switches them back) on streaming.
  reportGpu() {
    if (!this.model.get("gpu")) return;
    if (!this.gpuReason && !this.gpuReadySent) {
      this.gpuReadySent = true;
      this.model.send({ type: "gpu_ready" });
    } else if (this.gpuReason && !this.gpuReported) {
      this.gpuReported = true;
      this.model.send({ type: "gpu_unavailable", reason: this.gpuReason });
    }
  },

  failGpu(reason) {
    this.gpuReason = reason;
    if (this.gpu) this.gpu.drawUniforms.fwbGpu.value = false;
    this.reportGpu();
    this.updateGpuNote();
  },

  updateGpuNote() {
    if (!this.gpuNote) return;
    let text = "";
    if (!this.model.get("gpu")) text = "Vertices stream from the kernel (Viewport.gpu = False)";
    else if (this.gpuReason) text = `GPU evaluation unavailable (${this.gpuReason}): vertices stream from the kernel`;
    this.gpuNote.textContent = text;
    this.gpuNote.style.display = text ? "block" : "none";
    this.el.setAttribute("data-gpu-note", text);
  },

  gpuOn() {
    return !!(this.gpu && !this.gpuReason && this.store.gpuReady());
  },

  // New geometry in GPU mode: evaluate both passes (from uploadGeometry). False: not GPU.
  gpuFrame() {
    const on = this.gpuOn();
    if (this.gpu) this.gpu.drawUniforms.fwbGpu.value = on;
    this.el.setAttribute("data-gpu", on ? "1" : "0");
    if (this.lastDetail === "draft" && !on) this.showDetail("full"); // back to streaming
    if (!on) return false;
    const again = gpuUnsupported(this.renderer, this.store); // the rig may outgrow the textures
    if (again) { this.failGpu(again); this.showDetail("full"); return false; }
    try {
      if (!this.gpu.sync(this.store)) return false;
      this.lastFrameDraft = this.draftWanted();
      if (this.lastFrameDraft) {
        this.drawDraft(); // ./gpu_draft.js: the full mesh follows when the changes pause
      } else {
        this.gpu.evaluate();
        this.fullStale = false;
        this.forceFull = false;
        this.showDetail("full");
        if (this.fullFrameMs === null) setTimeout(() => { if (this.gpuOn()) this.calibrate(); }, 0);
      }
    } catch (err) {
      this.failGpu(`GPU evaluation failed: ${err}`);
      this.showDetail("full");
      return false;
    }
    this.el.setAttribute("data-gpu-texture-bytes", String(this.gpu.textureBytes()));
    this.el.setAttribute("data-gpu-evaluations", String(this.gpu.evaluations));
    this.gpuDrawn = true;
    this.countClipFrame();
    // the rows the CPU draws every frame, evaluated on the CPU (no readback stall)
    this.store.evaluateRows(this.cpuRowIds());
    return true;
  },

  // GPU path: make the CPU positions of vertex `ids` current (the CPU evaluates those rows).
  cpuRows(ids) {
    if (this.gpuDrawn && this.gpu && this.gpuOn()) this.store.evaluateRows(ids);
  },

  // Vertices whose positions the CPU needs every frame: markers, feature graph, probes.
  cpuRowIds() {
    const ids = [];
    if (this.markerIds) for (const i of this.markerIds) ids.push(i);
    const fg = this.featureGraph;
    if (fg && fg.edges && fg.edges.length && this.model.get("feature_graph")) {
      for (const i of fg.edges) ids.push(i);
    }
    const probe = typed(this.model.get("_probe_ids"), Uint32Array);
    if (probe) for (const i of probe) ids.push(i);
    return ids;
  },

  readBack() {
    const s = this.store;
    if (!this.positionAttr) return;
    this.ensureFullEvaluated(); // after a draft frame
    this.gpu.readPositions(this.positionAttr.array);
    if (s.positions && s.positions.length === this.positionAttr.array.length) s.positions.set(this.positionAttr.array);
    this.positionAttr.needsUpdate = true;
    this.cpuSeen = s.positionsVersion;
  },

  // Before CPU work on positions (picking, projecting): make them current.
  ensureCpuPositions() {
    if (!this.gpu || !this.gpuDrawn || !this.gpuOn()) return;
    if (this.geometryDirty) {
      this.geometryDirty = false;
      this.uploadGeometry();
      this.geometryDirty = true; // still draw it on the next frame
    }
    if (this.cpuSeen !== this.store.positionsVersion) this.readBack();
  },

  // Test hook: the GPU's evaluated positions (n*3), read back now.
  gpuPositions() {
    if (!this.gpuOn()) return null;
    this.ensureCpuPositions();
    return this.gpu.readPositions(new Float32Array(this.store.gpu.n * 3));
  },

  // Playback in the browser (./gpu_clip.js): draw each new frame of the clip at once.
  clipStarted() {
    this.clipFrames = 0;
    this.clipWall0 = performance.now();
    this.el.setAttribute("data-clip-playing", "1");
  },

  // A handle drag moved (./tools.js): move the face in the page before the kernel answers
  // (./gpu_local.js predictDrag; the kernel's parameters follow and win).
  predictDrag(d) {
    if (!this.gpuOn() || !this.gpuDrawn) return;
    const mirror = this.model.get("symmetric") && this.markerMirror ? this.markerMirror[d.index] : -1;
    this.store.predictDrag(d, mirror);
  },

  // New parameters from the page itself (Store.pageParamsChanged: a clip frame, a slider, a
  // drag): draw now.
  // At once unless the GPU still draws the last frame (then at the next display frame):
  // software WebGL queues frames, and a queue is latency.
  paramsChanged() {
    this.geometryDirty = true;
    if (this.pending) return; // a render is already due this frame
    if (this.gpuBusy()) this.requestRender();
    else this.renderNow();
  },

  gpuBusy() {
    const f = this.frameFence;
    if (!f) return false;
    const gl = this.renderer.getContext();
    if (gl.getSyncParameter(f, gl.SYNC_STATUS) !== gl.SIGNALED) return true;
    gl.deleteSync(f);
    this.frameFence = null;
    return false;
  },

  // After a GPU frame: a fence the next page-driven frame waits for (gpuBusy).
  fenceFrame() {
    const gl = this.renderer.getContext();
    if (this.frameFence) gl.deleteSync(this.frameFence);
    this.frameFence = gl.fenceSync(gl.SYNC_GPU_COMMANDS_COMPLETE, 0);
    gl.flush();
  },

  // A clip frame was evaluated (from gpuFrame): count it for data-clip-frames / -fps.
  countClipFrame() {
    const p = this.store.clipPlay;
    if (!p) return;
    this.clipFrames = (this.clipFrames || 0) + 1;
    const secs = (performance.now() - this.clipWall0) / 1000;
    this.el.setAttribute("data-clip-frames", String(this.clipFrames));
    this.el.setAttribute("data-clip-fps", secs > 0 ? (this.clipFrames / secs).toFixed(2) : "0");
    this.el.setAttribute("data-clip-time", String(p.time));
  },

  clipStopped() {
    this.el.setAttribute("data-clip-playing", "0");
  },

  // Test hook: the GPU's normals (n*3), read back now.
  gpuNormals() {
    if (!this.gpuOn()) return null;
    this.ensureCpuPositions();
    this.ensureFullEvaluated();
    return this.gpu.readNormals(new Float32Array(this.store.gpu.n * 3));
  },

  disposeGpu() {
    delete this.el.fwbGpuState;
    delete this.el.fwbGpuTime;
    delete this.el.fwbGpuNormals;
    this.model.off("change:gpu", this.onGpuTrait);
    this.model.off("change:_gpu_mode", this.onGpuTrait);
    this.disposeDraft();
    if (this.frameFence) this.renderer.getContext().deleteSync(this.frameFence);
    if (this.gpu) this.gpu.dispose();
  },
};
