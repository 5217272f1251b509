// GPU evaluation of the rig for one view (Python side: widgets/viewport/gpu.py).
//
// Two passes into float render targets, one texel per vertex (vertex i at (i % W, i / W)):
//   1. positions: p = M (base + a Σ_k w_k δ_k + c B u_H), base = neutral + residual, with the
//      deltas vertex-major and sparse (per vertex (offset, count) into (dx, dy, dz, shape)
//      entries), B the shell basis (ceil(H/4) RGBA texels per vertex), w a k-texel row, u_H
//      and M uniforms;
//   2. normals: area-weighted, the sum of cross(p_b - p_i, p_c - p_i) over the faces (i, b, c)
//      around vertex i (the same sum as util.js computeNormals), the faces walked as fans of
//      neighbours (each neighbour fetched once; a new fan starts where the next face does not
//      share an edge with the last).
// The view's materials read both targets in the vertex shader by gl_VertexID (patchMaterial).
// The rig arrays come from the Store (./sync.js, padded to the texture width once per model);
// each view owns its textures, because each view has its own WebGL context.
import * as THREE from "three";

export const TEX_WIDTH = 4096;
const MAX_HQ = 64; // ≤ 256 handles in the shell uniforms
const MAX_KQ = 64; // ≤ 256 shapes in the weight uniforms

// precision and the texel address of item i, shared by both passes
const PREAMBLE = `precision highp float; precision highp int;
precision highp sampler2D; precision highp usampler2D;
ivec2 at(int i) { return ivec2(i % ${TEX_WIDTH}, i / ${TEX_WIDTH}); }
`;

const EVAL_FS = `
${PREAMBLE}uniform sampler2D baseTex;
uniform sampler2D gainTex;
uniform usampler2D indexTex;
uniform sampler2D entryTex;
uniform vec4 wts[${MAX_KQ}];
uniform sampler2D basisTex;
uniform vec4 uHx[${MAX_HQ}];
uniform vec4 uHy[${MAX_HQ}];
uniform vec4 uHz[${MAX_HQ}];
uniform int hq;
uniform mat4 head;
uniform int n;
uniform usampler2D idTex;
uniform bool useIds;
out vec4 outColor;
void main() {
  int t = int(gl_FragCoord.y) * ${TEX_WIDTH} + int(gl_FragCoord.x);
  if (t >= n) { outColor = vec4(0.0); return; }
  // texel t holds vertex v: the same for the whole mesh, a subset for the draft (./gpu_draft.js)
  int v = useIds ? int(texelFetch(idTex, at(t), 0).x) : t;
  vec4 base = texelFetch(baseTex, at(v), 0);
  vec2 g = texelFetch(gainTex, at(v), 0).xy;
  uvec2 oc = texelFetch(indexTex, at(v), 0).xy;
  vec3 blend = vec3(0.0);
  int off = int(oc.x);
  int cnt = int(oc.y);
  for (int e = 0; e < cnt; e++) {
    vec4 d = texelFetch(entryTex, at(off + e), 0);
    int s = int(d.w + 0.5);
    float w = wts[s >> 2][s & 3];
    blend += w * d.xyz;
  }
  vec3 shell = vec3(0.0);
  for (int j = 0; j < hq; j++) {
    vec4 b = texelFetch(basisTex, at(v * hq + j), 0);
    shell += vec3(dot(b, uHx[j]), dot(b, uHy[j]), dot(b, uHz[j]));
  }
  vec3 p = base.xyz + g.x * blend + g.y * shell;
  outColor = vec4((head * vec4(p, 1.0)).xyz, 1.0);
}`;

const NORMAL_FS = `
${PREAMBLE}uniform sampler2D posTex;
uniform usampler2D adjIndexTex;
uniform usampler2D adjTex;
uniform int n;
out vec4 outColor;
void main() {
  int v = int(gl_FragCoord.y) * ${TEX_WIDTH} + int(gl_FragCoord.x);
  if (v >= n) { outColor = vec4(0.0); return; }
  vec3 p = texelFetch(posTex, at(v), 0).xyz;
  uvec2 oc = texelFetch(adjIndexTex, at(v), 0).xy;
  vec3 nrm = vec3(0.0);
  int off = int(oc.x);
  int cnt = int(oc.y);
  vec3 prev = vec3(0.0);
  for (int e = 0; e < cnt; e++) {
    uvec2 nf = texelFetch(adjTex, at(off + e), 0).xy; // (neighbour, starts a new fan)
    vec3 cur = texelFetch(posTex, at(int(nf.x)), 0).xyz - p;
    if (nf.y == 0u) nrm += cross(prev, cur);
    prev = cur;
  }
  float l = length(nrm);
  outColor = vec4(l > 0.0 ? nrm / l : nrm, 1.0);
}`;

const QUAD_VS = `
in vec3 position;
void main() { gl_Position = vec4(position.xy, 0.0, 1.0); }`;

const RT_OPTIONS = {
  type: THREE.FloatType, format: THREE.RGBAFormat, depthBuffer: false,
  minFilter: THREE.NearestFilter, magFilter: THREE.NearestFilter, generateMipmaps: false,
};

// rows of a TEX_WIDTH-wide texture holding `count` texels
export function texRows(count) {
  return Math.max(1, Math.ceil(count / TEX_WIDTH));
}

// A copy of `src` padded to whole rows of `channels`-component texels.
export function padded(src, channels, Ctor = src.constructor) {
  const texels = Math.ceil(src.length / channels);
  const out = new Ctor(texRows(texels) * TEX_WIDTH * channels);
  out.set(src);
  return out;
}

function dataTexture(data, channels, type, width = TEX_WIDTH) {
  const height = data.length / channels / width;
  const integer = type === THREE.UnsignedIntType;
  const formats = integer
    ? { 1: THREE.RedIntegerFormat, 2: THREE.RGIntegerFormat, 4: THREE.RGBAIntegerFormat }
    : { 1: THREE.RedFormat, 2: THREE.RGFormat, 4: THREE.RGBAFormat };
  const suffix = integer ? "32UI" : type === THREE.HalfFloatType ? "16F" : "32F";
  const names = { 1: "R", 2: "RG", 4: "RGBA" };
  const t = new THREE.DataTexture(data, width, height, formats[channels], type);
  t.internalFormat = names[channels] + suffix;
  t.minFilter = THREE.NearestFilter;
  t.magFilter = THREE.NearestFilter;
  t.generateMipmaps = false;
  t.flipY = false;
  t.unpackAlignment = 1;
  t.needsUpdate = true;
  return t;
}

// Can this renderer evaluate on the GPU? "" when yes, else the reason (shown in the view).
export function gpuUnsupported(renderer, store) {
  if (globalThis.fwbDisableGpu) return "disabled by the page (fwbDisableGpu)";
  const gl = renderer.getContext();
  if (typeof WebGL2RenderingContext === "undefined" || !(gl instanceof WebGL2RenderingContext)) {
    return "WebGL2 is not available";
  }
  if (!gl.getExtension("EXT_color_buffer_float")) return "float render targets (EXT_color_buffer_float) are missing";
  const maxTex = gl.getParameter(gl.MAX_TEXTURE_SIZE);
  if (maxTex < TEX_WIDTH) return `the largest texture (${maxTex}) is smaller than ${TEX_WIDTH}`;
  if (gl.getParameter(gl.MAX_VERTEX_TEXTURE_IMAGE_UNITS) < 2) return "the vertex shader cannot read textures";
  if (gl.getParameter(gl.MAX_FRAGMENT_UNIFORM_VECTORS) < MAX_KQ + 3 * MAX_HQ + 8) {
    return "too few fragment uniforms";
  }
  const g = store && store.gpu;
  if (g) {
    const rows = Math.max(g.entryRows || 1, g.basisRows || 1, texRows(g.n));
    if (rows > maxTex) return `the rig needs ${rows} texture rows, the largest texture has ${maxTex}`;
    if (g.hq > MAX_HQ) return `more than ${4 * MAX_HQ} shell handles`;
    if (g.k > 4 * MAX_KQ) return `more than ${4 * MAX_KQ} shapes`;
  }
  return "";
}

export class GpuMorph {
  constructor(renderer) {
    this.renderer = renderer;
    this.textures = {};
    this.seen = {}; // store versions the textures were built from
    const dummyF = dataTexture(new Float32Array(4), 4, THREE.FloatType, 1);
    const dummyU = dataTexture(new Uint32Array(4), 4, THREE.UnsignedIntType, 1);
    this.dummyF = dummyF;
    this.dummyU = dummyU;
    this.evalUniforms = {
      baseTex: { value: dummyF }, gainTex: { value: dummyF }, indexTex: { value: dummyU },
      entryTex: { value: dummyF }, basisTex: { value: dummyF },
      wts: { value: Array.from({ length: MAX_KQ }, () => new THREE.Vector4()) },
      uHx: { value: Array.from({ length: MAX_HQ }, () => new THREE.Vector4()) },
      uHy: { value: Array.from({ length: MAX_HQ }, () => new THREE.Vector4()) },
      uHz: { value: Array.from({ length: MAX_HQ }, () => new THREE.Vector4()) },
      hq: { value: 0 }, head: { value: new THREE.Matrix4() }, n: { value: 0 },
      idTex: { value: dummyU }, useIds: { value: false },
    };
    this.normalUniforms = {
      posTex: { value: dummyF }, adjIndexTex: { value: dummyU }, adjTex: { value: dummyU }, n: { value: 0 },
    };
    const quad = new THREE.BufferGeometry();
    quad.setAttribute("position", new THREE.BufferAttribute(new Float32Array([-1, -1, 0, 3, -1, 0, -1, 3, 0]), 3));
    const mat = (fs, uniforms) => new THREE.RawShaderMaterial({
      vertexShader: QUAD_VS, fragmentShader: fs, uniforms, glslVersion: THREE.GLSL3,
      depthTest: false, depthWrite: false,
    });
    this.evalMesh = new THREE.Mesh(quad, mat(EVAL_FS, this.evalUniforms));
    this.normalMesh = new THREE.Mesh(quad, mat(NORMAL_FS, this.normalUniforms));
    for (const m of [this.evalMesh, this.normalMesh]) m.frustumCulled = false;
    this.evalScene = new THREE.Scene();
    this.evalScene.add(this.evalMesh);
    this.normalScene = new THREE.Scene();
    this.normalScene.add(this.normalMesh);
    this.quadCamera = new THREE.OrthographicCamera(-1, 1, 1, -1, 0, 1);
    // what the view's materials read (patchMaterial)
    this.drawUniforms = { fwbPos: { value: dummyF }, fwbNrm: { value: dummyF }, fwbGpu: { value: false } };
    this.posRT = null;
    this.nrmRT = null;
    this.draft = null; // the draft's vertex ids, fans and targets (setDraft)
    this.draftUniforms = { fwbPos: { value: dummyF }, fwbNrm: { value: dummyF }, fwbGpu: { value: true } };
    this.n = 0;
    this.evaluations = 0;
  }

  // Build or refresh the textures from the store's rig (only what changed since last time).
  sync(store) {
    const g = store.gpu;
    if (!g) return false;
    const T = this.textures;
    const set = (name, tex) => {
      if (T[name]) T[name].dispose();
      T[name] = tex;
    };
    if (this.seen.morph !== g.morphVersion) {
      set("index", dataTexture(g.index, 2, THREE.UnsignedIntType));
      set("entry", dataTexture(g.entries, 4, g.half ? THREE.HalfFloatType : THREE.FloatType));
      this.seen.morph = g.morphVersion;
      this.n = g.n;
      const rows = texRows(g.n);
      if (!this.posRT || this.posRT.height !== rows) {
        if (this.posRT) { this.posRT.dispose(); this.nrmRT.dispose(); }
        this.posRT = new THREE.WebGLRenderTarget(TEX_WIDTH, rows, RT_OPTIONS);
        this.nrmRT = new THREE.WebGLRenderTarget(TEX_WIDTH, rows, RT_OPTIONS);
      }
    }
    if (this.seen.base !== g.baseVersion) {
      if (T.base && T.base.image.data === g.base) T.base.needsUpdate = true;
      else set("base", dataTexture(g.base, 4, THREE.FloatType));
      this.seen.base = g.baseVersion;
    }
    if (this.seen.gain !== g.gainVersion) {
      set("gain", dataTexture(g.gain, 2, THREE.FloatType));
      this.seen.gain = g.gainVersion;
    }
    if (this.seen.basis !== g.basisVersion) {
      set("basis", g.hq ? dataTexture(g.basis, 4, THREE.FloatType) : null);
      this.seen.basis = g.basisVersion;
    }
    if (this.seen.topology !== store.topologyVersion && store.faces) {
      const { index, pairs } = faceFans(store.faces, g.n);
      set("adjIndex", dataTexture(index, 2, THREE.UnsignedIntType));
      set("adj", dataTexture(pairs, 2, THREE.UnsignedIntType));
      this.seen.topology = store.topologyVersion;
    }
    // parameters: weights (a k-texel row), shell offsets, head pose
    const P = store.gpuParams;
    const k = g.k;
    if (P && P.length >= k + 3 * g.hu + 16) {
      const u = this.evalUniforms;
      const wts = u.wts.value;
      for (let j = 0; j < MAX_KQ; j++) {
        const at = (q) => (4 * j + q < k ? P[4 * j + q] : 0);
        wts[j].set(at(0), at(1), at(2), at(3));
      }
      let any = false;
      for (let j = 0; j < g.hq; j++) {
        for (const [c, arr] of [[0, u.uHx.value], [1, u.uHy.value], [2, u.uHz.value]]) {
          const vals = [0, 0, 0, 0];
          for (let q = 0; q < 4; q++) {
            const h = 4 * j + q;
            if (h < g.hu) vals[q] = P[k + 3 * h + c];
            if (vals[q] !== 0) any = true;
          }
          arr[j].set(vals[0], vals[1], vals[2], vals[3]);
        }
      }
      u.hq.value = any && T.basis ? g.hq : 0; // no offsets: skip the shell loop
      u.head.value.fromArray(P, k + 3 * g.hu);
    }
    const u = this.evalUniforms;
    u.baseTex.value = T.base || this.dummyF;
    u.gainTex.value = T.gain || this.dummyF;
    u.indexTex.value = T.index || this.dummyU;
    u.entryTex.value = T.entry || this.dummyF;
    u.basisTex.value = T.basis || this.dummyF;
    return !!(T.base && T.gain && T.index && T.entry && this.posRT);
  }

  // Run both passes; the materials then draw the result.
  evaluate() {
    this.passes(this.posRT, this.nrmRT, this.n, null, this.textures.adjIndex, this.textures.adj);
    this.drawUniforms.fwbPos.value = this.posRT.texture;
    this.drawUniforms.fwbNrm.value = this.nrmRT.texture;
    this.evaluations += 1;
  }

  // Both passes for the draft's vertices only (texel t = vertex draft.ids[t]); its own
  // fans give its normals. The draft mesh (./gpu_draft.js) reads draftUniforms.
  evaluateDraft() {
    const d = this.draft;
    this.passes(d.posRT, d.nrmRT, d.m, d.ids, d.adjIndex, d.adj);
    this.draftUniforms.fwbPos.value = d.posRT.texture;
    this.draftUniforms.fwbNrm.value = d.nrmRT.texture;
    this.draftEvaluations = (this.draftEvaluations || 0) + 1;
  }

  passes(posRT, nrmRT, count, ids, adjIndex, adj) {
    const r = this.renderer;
    const prev = r.getRenderTarget();
    const clear = r.autoClear;
    r.autoClear = false;
    const eu = this.evalUniforms, nu = this.normalUniforms;
    eu.n.value = count;
    eu.useIds.value = !!ids;
    eu.idTex.value = ids || this.dummyU;
    r.setRenderTarget(posRT);
    r.render(this.evalScene, this.quadCamera);
    nu.n.value = count;
    nu.posTex.value = posRT.texture;
    nu.adjIndexTex.value = adjIndex || this.dummyU;
    nu.adjTex.value = adj || this.dummyU;
    r.setRenderTarget(nrmRT);
    r.render(this.normalScene, this.quadCamera);
    r.setRenderTarget(prev);
    r.autoClear = clear;
  }

  // The draft (./gpu_draft.js): `ids` (m) the vertices it keeps, `faces` its triangles in
  // draft numbering (0..m-1). Null drops it.
  setDraft(ids, faces) {
    this.dropDraft();
    if (!ids) return;
    const m = ids.length;
    const { index, pairs } = faceFans(faces, m);
    const rows = texRows(m);
    this.draft = {
      m, faces,
      ids: dataTexture(padded(ids, 1), 1, THREE.UnsignedIntType),
      adjIndex: dataTexture(index, 2, THREE.UnsignedIntType),
      adj: dataTexture(pairs, 2, THREE.UnsignedIntType),
      posRT: new THREE.WebGLRenderTarget(TEX_WIDTH, rows, RT_OPTIONS),
      nrmRT: new THREE.WebGLRenderTarget(TEX_WIDTH, rows, RT_OPTIONS),
    };
  }

  dropDraft() {
    const d = this.draft;
    if (!d) return;
    for (const t of [d.ids, d.adjIndex, d.adj, d.posRT, d.nrmRT]) t.dispose();
    this.draft = null;
  }

  // The evaluated positions (n*3) (a readback of the position target).
  readPositions(out) {
    const rows = this.posRT.height;
    if (!this.readBuf || this.readBuf.length !== TEX_WIDTH * rows * 4) {
      this.readBuf = new Float32Array(TEX_WIDTH * rows * 4);
    }
    this.renderer.readRenderTargetPixels(this.posRT, 0, 0, TEX_WIDTH, rows, this.readBuf);
    const B = this.readBuf;
    const n = Math.min(this.n, out.length / 3);
    for (let i = 0; i < n; i++) {
      out[3 * i] = B[4 * i]; out[3 * i + 1] = B[4 * i + 1]; out[3 * i + 2] = B[4 * i + 2];
    }
    return out;
  }

  // The evaluated normals (n*3) (a readback of the normal target; tests).
  readNormals(out) {
    const rows = this.nrmRT.height;
    const buf = new Float32Array(TEX_WIDTH * rows * 4);
    this.renderer.readRenderTargetPixels(this.nrmRT, 0, 0, TEX_WIDTH, rows, buf);
    const n = Math.min(this.n, out.length / 3);
    for (let i = 0; i < n; i++) {
      out[3 * i] = buf[4 * i]; out[3 * i + 1] = buf[4 * i + 1]; out[3 * i + 2] = buf[4 * i + 2];
    }
    return out;
  }

  // Bytes held in this view's textures and targets (the benchmark's texture memory).
  textureBytes() {
    let b = 0;
    const bpp = { RGBA32F: 16, RG32F: 8, R32F: 4, RGBA16F: 8, RG32UI: 8, RGBA32UI: 16 };
    for (const t of Object.values(this.textures)) {
      if (t) b += t.image.width * t.image.height * (bpp[t.internalFormat] || 16);
    }
    if (this.posRT) b += 2 * this.posRT.width * this.posRT.height * 16;
    const d = this.draft;
    if (d) b += d.ids.image.width * d.ids.image.height * 4 + 8 * d.adjIndex.image.width * (d.adjIndex.image.height + d.adj.image.height) + 2 * d.posRT.width * d.posRT.height * 16;
    return b;
  }

  dispose() {
    for (const t of Object.values(this.textures)) if (t) t.dispose();
    this.textures = {};
    this.dummyF.dispose();
    this.dummyU.dispose();
    if (this.posRT) { this.posRT.dispose(); this.nrmRT.dispose(); }
    this.dropDraft();
    this.evalMesh.geometry.dispose();
    this.evalMesh.material.dispose();
    this.normalMesh.material.dispose();
  }
}

// Per vertex i: (offset, count) into (neighbour, new fan) entries: the faces (i, b, c) around
// i in winding order, chained into fans b0 c0=b1 c1=b2 ... (a closed fan repeats its first
// neighbour at the end); each face adds cross(b - i, c - i) in the normal pass.
function faceFans(F, n) {
  const counts = new Uint32Array(n);
  for (let f = 0; f < F.length; f++) if (F[f] < n) counts[F[f]] += 1;
  const start = new Uint32Array(n + 1);
  for (let i = 0; i < n; i++) start[i + 1] = start[i] + counts[i];
  const fill = new Uint32Array(n);
  const B = new Uint32Array(start[n]), C = new Uint32Array(start[n]);
  for (let f = 0; f < F.length; f += 3) {
    const a = F[f], b = F[f + 1], c = F[f + 2];
    if (a >= n || b >= n || c >= n) continue;
    for (const [i, j, k] of [[a, b, c], [b, c, a], [c, a, b]]) {
      const at = start[i] + fill[i]++;
      B[at] = j; C[at] = k;
    }
  }
  const index = new Uint32Array(n * 2);
  const out = [];
  const used = new Uint8Array(16);
  for (let i = 0; i < n; i++) {
    const s0 = start[i], m = fill[i];
    index[2 * i] = out.length / 2;
    const seen = m <= 16 ? used : new Uint8Array(m);
    seen.fill(0, 0, m);
    let left = m;
    while (left > 0) {
      // start a fan at a face whose b is no other face's c (an open fan's first face)
      let f = -1;
      for (let x = 0; x < m && f < 0; x++) {
        if (seen[x]) continue;
        let opens = true;
        for (let y = 0; y < m; y++) if (!seen[y] && y !== x && C[s0 + y] === B[s0 + x]) { opens = false; break; }
        if (opens) f = x;
      }
      if (f < 0) for (let x = 0; x < m; x++) if (!seen[x]) { f = x; break; }
      out.push(B[s0 + f], 1);
      while (f >= 0) {
        seen[f] = 1; left -= 1;
        const c = C[s0 + f];
        out.push(c, 0);
        f = -1;
        for (let y = 0; y < m; y++) if (!seen[y] && B[s0 + y] === c) { f = y; break; }
      }
    }
    index[2 * i + 1] = out.length / 2 - index[2 * i];
  }
  return { index: padded(index, 2), pairs: padded(Uint32Array.from(out), 2) };
}

// Let a view's material draw the GPU positions and normals (when drawUniforms.fwbGpu is on).
export function patchMaterial(material, uniforms) {
  material.onBeforeCompile = (shader) => {
    Object.assign(shader.uniforms, uniforms);
    shader.vertexShader = shader.vertexShader
      .replace("#include <common>", `#include <common>
uniform highp sampler2D fwbPos;
uniform highp sampler2D fwbNrm;
uniform bool fwbGpu;
ivec2 fwbAt(int i) { return ivec2(i % ${TEX_WIDTH}, i / ${TEX_WIDTH}); }`)
      .replace("#include <beginnormal_vertex>", `vec3 objectNormal = fwbGpu ? texelFetch(fwbNrm, fwbAt(gl_VertexID), 0).xyz : vec3(normal);
#ifdef USE_TANGENT
vec3 objectTangent = vec3(tangent.xyz);
#endif`)
      .replace("#include <begin_vertex>", `vec3 transformed = fwbGpu ? texelFetch(fwbPos, fwbAt(gl_VertexID), 0).xyz : vec3(position);`);
  };
  material.customProgramCacheKey = () => "fwb-gpu-morph";
  material.needsUpdate = true;
}
