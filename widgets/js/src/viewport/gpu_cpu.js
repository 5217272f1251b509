// The GPU path's evaluation of single vertices on the CPU (the same sum as gpu_morph.js's
// position pass), for the few rows the CPU needs every frame: handle markers, feature-graph
// end points, probes. Reading the whole position target back stalls the pipeline, so that
// is left to picking (View.ensureCpuPositions). Methods mixed into the Store (./sync.js).

// IEEE half -> float
function halfToFloat(h) {
  const s = h & 0x8000 ? -1 : 1;
  const e = (h >> 10) & 0x1f;
  const f = h & 0x3ff;
  if (e === 0) return s * f * 2 ** -24;
  if (e === 31) return f ? NaN : s * Infinity;
  return s * (1 + f / 1024) * 2 ** (e - 15);
}

export const cpuRowMethods = {
  // Write the evaluated positions of vertex `ids` into this.positions (GPU mode only).
  evaluateRows(ids) {
    const g = this.gpu;
    const P = this.gpuParams;
    const out = this.positions;
    if (!g || !P || !out || !ids) return;
    const k = g.k, hu = g.hu;
    const E = g.entries, I = g.index, B = g.base, G = g.gain, S = g.basis;
    const hq = g.hq;
    const m = k + 3 * hu; // head matrix, column-major
    for (const i of ids) {
      if (i >= g.n) continue;
      let bx = 0, by = 0, bz = 0;
      const off = I[2 * i], cnt = I[2 * i + 1];
      for (let e = off; e < off + cnt; e++) {
        const q = 4 * e;
        const dx = g.half ? halfToFloat(E[q]) : E[q];
        const dy = g.half ? halfToFloat(E[q + 1]) : E[q + 1];
        const dz = g.half ? halfToFloat(E[q + 2]) : E[q + 2];
        const s = Math.round(g.half ? halfToFloat(E[q + 3]) : E[q + 3]);
        const w = P[s];
        bx += w * dx; by += w * dy; bz += w * dz;
      }
      let sx = 0, sy = 0, sz = 0;
      if (S && hu) {
        for (let j = 0; j < hu; j++) {
          const b = S[i * hq * 4 + j];
          if (b === 0) continue;
          sx += b * P[k + 3 * j]; sy += b * P[k + 3 * j + 1]; sz += b * P[k + 3 * j + 2];
        }
      }
      const a = G[2 * i], c = G[2 * i + 1];
      const px = B[4 * i] + a * bx + c * sx;
      const py = B[4 * i + 1] + a * by + c * sy;
      const pz = B[4 * i + 2] + a * bz + c * sz;
      out[3 * i] = P[m] * px + P[m + 4] * py + P[m + 8] * pz + P[m + 12];
      out[3 * i + 1] = P[m + 1] * px + P[m + 5] * py + P[m + 9] * pz + P[m + 13];
      out[3 * i + 2] = P[m + 2] * px + P[m + 6] * py + P[m + 10] * pz + P[m + 14];
    }
  },
};
