// Front end of widgets.Viewport: draws the FaceModel's evaluated vertices with three.js.
//
// Why hand-written instead of an off-the-shelf viewer (pythreejs, pyvista's trame backend):
// the workbench needs binary, partial geometry updates (only the vertices a slider moved),
// camera orbit that never touches the kernel, and test hooks (data-* attributes) that
// browser tests use to aim the mouse and to wait for frames. None of the existing widgets
// give all three; the code has no dependency but three.js.
////
// Modules (Python side: widgets/viewport/):
//   viewport/sync.js           Store: the geometry and surface tint Python sent (one per model)
//   viewport/scene.js          View: renderer, camera, render loop, test hooks (one per display)
//   viewport/markers.js        markers;  viewport/picking.js  rays, marker picks
//   viewport/tools.js          marker and brush tools: pointer events -> gestures
//   viewport/gestures.js       GestureClient: the ONE gesture protocol (start/move/end/cancel,
//                              one message in flight, acks) used by every tool
//   viewport/feature_graph.js  feature-graph strain overlay
//   viewport/gpu_morph.js      the rig evaluated on the GPU (float render targets), and
//   viewport/gpu_view.js       its use by a view: readback for picking, the fallback note
//   shared/playback.js         which timelines play (draft resolution), shared with timeline.js
// All views of one widget model share one geometry store (state lives in the model, not in
// the view), so a second display of the same widget shows the same frame.
import { FeatureGraphOverlay } from "./viewport/feature_graph.js";
import { PointOverlay } from "./viewport/point_overlay.js";
import { View } from "./viewport/scene.js";
import { watchSliderPointer } from "./viewport/slider_pointer.js";
import { Store } from "./viewport/sync.js";

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
    store.loadTintFull();
    store.initLocal(); // shape sliders move the face in the page first (./viewport/gpu_local.js)
    const unwatchSliders = watchSliderPointer(model); // the page says when a slider drag ends
    const onFull = () => store.loadFull();
    const onTintFull = () => store.loadTintFull();
    const onRig = () => { store.loadGpuRig(); store.notify(); };
    const onParamsTrait = () => store.gpuParamsTraitChanged();
    const onMsg = (content, buffers) => {
      if (!content) return;
      if (content.type === "gpu_play") store.playClip(content);
      else if (content.type === "gpu_stop") store.stopClip();
      else if (content.type === "gpu_params") {
        store.applyGpuParams(content, buffers || []);
        if (content.seq != null) for (const v of store.views) v.onAck(content);
      }
      else if (content.type === "patch") {
        store.applyPatch(content, buffers || []);
        // The patch of a gesture message doubles as its acknowledgement (gestures.js).
        if (content.seq != null) for (const v of store.views) v.onAck(content);
      }
      else if (content.type === "drag_ack") for (const v of store.views) v.onAck(content);
      else if (content.type === "drag_cancel") for (const v of store.views) v.onCancel("drag", content);
      else if (content.type === "tint_patch") store.applyTintPatch(content, buffers || []);
      else if (content.type === "stroke_ack") for (const v of store.views) v.onAck(content);
      else if (content.type === "stroke_cancel") for (const v of store.views) v.onCancel("stroke", content);
    };
    model.on("change:_version", onFull);
    model.on("change:_topology", onFull);
    model.on("change:_tint_version", onTintFull);
    model.on("change:_gpu_meta", onRig);
    model.on("change:_gpu_params", onParamsTrait);
    model.on("msg:custom", onMsg);
    return () => {
      model.off("change:_version", onFull);
      model.off("change:_topology", onFull);
      model.off("change:_tint_version", onTintFull);
      model.off("change:_gpu_meta", onRig);
      model.off("change:_gpu_params", onParamsTrait);
      model.off("msg:custom", onMsg);
      unwatchSliders();
      store.disposeLocal();
      STORES.delete(model.get("_uid"));
    };
  },

  render({ model, el }) {
    const store = storeFor(model);
    if (!store.positions) store.loadFull();
    store.loadTintFull();
    const view = new View(store, model, el);
    store.views.add(view);
    const featureGraph = new FeatureGraphOverlay(view, model); // feature-graph overlay
    view.featureGraph = featureGraph;
    const pointOverlay = new PointOverlay(view, model); // free points (capture input)
    const handlers = {
      "change:wireframe": () => { view.updateWireframe(); view.requestRender(); },
      "change:_vertex_colors": () => { view.updateColors(); view.requestRender(); },
      "change:component_visible": () => { view.updateIndex(); view.requestRender(); },
      "change:_markers": () => { view.refreshMarkerCache(); view.requestRender(); },
      "change:_marker_mirror": () => { view.refreshMarkerCache(); view.requestRender(); },
      "change:selected_marker": () => { view.markersDirty = true; view.requestRender(); },
      "change:symmetric": () => { view.markersDirty = true; view.requestRender(); },
      "change:tool": () => view.updateTool(),
      "change:_tool_kinds": () => view.updateTool(),
      "change:brush_radius": () => view.tools?.stroke.brushSettingsChanged(),
      "change:brush_mirror": () => view.tools?.stroke.brushSettingsChanged(),
      "change:_probe_ids": () => view.writeProbe(),
      "change:_error": () => view.updateError(),
      "change:height": () => view.resize(),
    };
    for (const [ev, fn] of Object.entries(handlers)) model.on(ev, fn);
    return () => {
      for (const [ev, fn] of Object.entries(handlers)) model.off(ev, fn);
      store.views.delete(view);
      featureGraph.dispose();
      pointOverlay.dispose();
      view.dispose();
    };
  },
};
