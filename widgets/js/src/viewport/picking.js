// Picking on a view: markers under the pointer, the ray's hit on the drawn surface, and
// the pointer on a plane. Methods mixed into View (they read its camera, geometry, markers).
import * as THREE from "three";

export const pickingMethods = {
  ndc(clientX, clientY) {
    const rect = this.renderer.domElement.getBoundingClientRect();
    return new THREE.Vector2(
      ((clientX - rect.left) / rect.width) * 2 - 1,
      -((clientY - rect.top) / rect.height) * 2 + 1,
    );
  },

  // Marker under the pointer (screen distance, nearest first), or -1. With `visible`,
  // markers hidden behind the surface (seen from the back of the head) are skipped.
  pickMarker(clientX, clientY, visible) {
    const ids = this.markerIds;
    if (!ids.length || !this.store.positions) return -1;
    this.ensureCpuPositions();
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
  },

  // Nearest hit of the pointer ray with the drawn (visible) triangles, in the shape of a
  // three.js intersection ({distance, point, face: {a, b, c, normal}}), or null.
  // A flat Moller-Trumbore loop over the typed arrays instead of Raycaster.intersectObject:
  // three.js's generic path (bounding sphere of the deformed mesh + per-triangle Vector3
  // work) took 7 ms at 25k and 22 ms at 100k vertices per pointer event while painting;
  // this loop is several times faster and needs no bounds (the mesh has no transform).
  raycastSurface(clientX, clientY) {
    if (!this.positionAttr || !this.geometry.index) return null;
    this.ensureCpuPositions();
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
  },

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
  },

  rayPlane(clientX, clientY, plane) {
    this.raycaster.setFromCamera(this.ndc(clientX, clientY), this.camera);
    return this.raycaster.ray.intersectPlane(plane, new THREE.Vector3());
  },

};
