// Which timelines are playing, for the viewports of the same face model (imported by
// timeline.js and by the viewport).
//
// The viewport and the timeline are two anywidget bundles (two ES module instances), so a
// module-level Map would not be shared between them: the registry lives on globalThis under
// a Symbol.for key, a small typed channel rather than a page-wide DOM event. Entries are
// keyed by the face model's scene key (the widgets' `_scene` trait: the same FaceModel
// gives the same key); a timeline without one ("") counts for every viewport.

const KEY = Symbol.for("face-workbench.playback.v1");

function registry() {
  let r = globalThis[KEY];
  if (!r) {
    r = { playing: new Map(), listeners: new Set() }; // source id -> scene key
    globalThis[KEY] = r;
  }
  return r;
}

// A timeline (`source`, unique per view) starts or stops playing the face model `scene`.
export function announcePlayback(source, scene, playing) {
  const r = registry();
  if (playing) r.playing.set(source, scene || "");
  else if (!r.playing.delete(source)) return;
  for (const fn of Array.from(r.listeners)) {
    try { fn(); } catch (err) { console.error("playback listener", err); } // eslint-disable-line no-console
  }
}

// Is any timeline of the face model `scene` (or of no particular model) playing?
export function isPlaying(scene) {
  for (const s of registry().playing.values()) if (s === "" || s === (scene || "")) return true;
  return false;
}

// Call fn() whenever playback starts or stops anywhere; returns the unsubscribe function.
export function onPlayback(fn) {
  const r = registry();
  r.listeners.add(fn);
  return () => r.listeners.delete(fn);
}
