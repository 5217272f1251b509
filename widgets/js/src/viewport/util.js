// Small helpers and constants shared by the viewport's modules (no state).
import * as THREE from "three";

// ---------------------------------------------------------------------------------------
// binary helpers: the widget protocol hands us DataView (state) or DataView/ArrayBuffer
// (custom message buffers); typed-array views need aligned offsets, so copy if unaligned.

export function typed(value, Ctor) {
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
export function computeNormals(P, F, N) {
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
export const COMPONENT_COLORS = [
  [/^skin|head|face|body/i, [0.86, 0.68, 0.58]],
  [/eyelash|brow_hair|eyebrow/i, [0.12, 0.09, 0.07]],
  [/iris|pupil|cornea/i, [0.25, 0.35, 0.45]],
  [/eye/i, [0.93, 0.93, 0.9]],
  [/teeth|tooth/i, [0.95, 0.93, 0.85]],
  [/tongue/i, [0.8, 0.4, 0.42]],
  [/gum/i, [0.85, 0.45, 0.45]],
];
export const SKIN = [0.86, 0.68, 0.58];

// Marker colours (sRGB): idle, hovered, dragged/selected, mirror of the active one.
export const MARKER_COLOR = 0xff8c1a;
export const MARKER_HOVER = 0xffe14d;
export const MARKER_SELECTED = 0x2ee6ff;
export const MARKER_MIRROR = 0xd17aff;

// Weight-map overlay: colour = mix(component colour, TINT_COLOR, TINT_STRENGTH * weight).
export const TINT_COLOR = [0.95, 0.1, 0.85]; // sRGB magenta
export const TINT_STRENGTH = 0.85;
export const BRUSH_COLOR = 0xfff27a;
export const MAX_QUEUE = 8; // most dab vertices per stroke message

export function colorForComponent(name) {
  for (const [re, rgb] of COMPONENT_COLORS) if (re.test(name || "")) return rgb;
  return SKIN;
}

export function srgbToLinear(c) {
  return c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4);
}

// ---------------------------------------------------------------------------------------
// Software WebGL (SwiftShader, llvmpipe: a machine without a GPU) is fill-rate bound:
// measured on the 2-core reference machine (benchmarks/bench_playback.py), MSAA doubles
// the time the GPU process needs per frame and every frame is read back for software
// compositing. There the view draws without MSAA and, while a timeline plays, at half
// resolution ("draft"); the full-resolution frame is drawn again as soon as playback stops.
let SOFTWARE_WEBGL = null;
export function softwareWebGL() {
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
export const DRAFT_PIXEL_RATIO = 0.5; // of the device pixel ratio, while a timeline plays
