// How much larger than the usual size each point of a box's surface cloud must be drawn for its
// face to show no gaps.
//
// Why: the worker's preview keeps every k-th point of the cloud in scan order
// (prismcore.scan.cloud.decimate, k about 6 for a 600,000-point scan), and scan order is row by row
// over each face. Where a face's row length is close to a multiple of k, the points kept line up
// in columns k pixels apart for many rows running: slits wider than a point, across the face.
// Through them the faces behind showed, and in depth colours the back face is the far end of the
// ramp (yellow on the front's dark purple): bright dotted streaks across the front face (photo
// colours showed the same slits, fainter). A size for the whole cloud from its mean spacing
// cannot see them; each point here is sized to reach its nearest neighbour on either side of it
// along its face (in four directions), so the slits close and the rest keeps its detail.

import type * as THREE from "three";

/** Per point, the factor (1 to 2: neighbours are looked for within two sizes) by which to enlarge it beyond `size` (the world-sized side of
 * a point as usually drawn) so that it meets its neighbours on its face of `bounds`. Points on
 * no face (a volume cloud's inside) keep 1. */
export function gapScales(position: THREE.BufferAttribute | THREE.InterleavedBufferAttribute,
  bounds: THREE.Box3, size: number): Float32Array {
  const count = position.count;
  const scales = new Float32Array(count).fill(1);
  if (!(size > 0) || count < 2) return scales;
  const lo = [bounds.min.x, bounds.min.y, bounds.min.z];
  const hi = [bounds.max.x, bounds.max.y, bounds.max.z];
  const tol = 0.25 * size;
  // Each point's face: the bounding box's plane nearest to it (axis * 2 + side), or -1.
  const face = new Int8Array(count).fill(-1);
  for (let i = 0; i < count; i++) {
    let best = tol;
    for (let axis = 0; axis < 3; axis++) {
      const v = position.getComponent(i, axis);
      const dLo = Math.abs(v - lo[axis]);
      const dHi = Math.abs(v - hi[axis]);
      if (dLo < best) [best, face[i]] = [dLo, axis * 2];
      if (dHi < best) [best, face[i]] = [dHi, axis * 2 + 1];
    }
  }
  for (let f = 0; f < 6; f++) faceScales(position, face, f, lo, hi, size, scales);
  return scales;
}

/** The scales of face `f`'s points: a grid of cells `size` wide over the face's plane, and per
 * point the nearest neighbour within two cells in each of four directions (right, left, down,
 * up: 90-degree wedges); a direction with none is the face's edge and is left out. */
function faceScales(position: THREE.BufferAttribute | THREE.InterleavedBufferAttribute, face: Int8Array,
  f: number, lo: number[], hi: number[], size: number, scales: Float32Array): void {
  const axis = f >> 1;
  const [a, b] = [(axis + 1) % 3, (axis + 2) % 3];
  const members: number[] = [];
  for (let i = 0; i < face.length; i++) if (face[i] === f) members.push(i);
  const n = members.length;
  if (n < 2) return;
  const cell = size;
  const nu = Math.max(1, Math.floor((hi[a] - lo[a]) / cell) + 1);
  const nv = Math.max(1, Math.floor((hi[b] - lo[b]) / cell) + 1);
  if (nu * nv > 4 * n + 1024) return; // far sparser than a surface (no use, and memory): leave 1
  const u = new Float64Array(n);
  const v = new Float64Array(n);
  const at = new Int32Array(n);
  const start = new Int32Array(nu * nv + 1);
  for (let k = 0; k < n; k++) {
    u[k] = position.getComponent(members[k], a);
    v[k] = position.getComponent(members[k], b);
    const cu = Math.min(nu - 1, Math.floor((u[k] - lo[a]) / cell));
    const cv = Math.min(nv - 1, Math.floor((v[k] - lo[b]) / cell));
    at[k] = cv * nu + cu;
    start[at[k] + 1]++;
  }
  for (let c = 0; c < nu * nv; c++) start[c + 1] += start[c];
  const order = new Int32Array(n);
  const fill = start.slice(0, nu * nv);
  for (let k = 0; k < n; k++) order[fill[at[k]]++] = k;
  const reach2 = (2 * cell) ** 2;
  const nearest = new Float64Array(4);
  for (let k = 0; k < n; k++) {
    nearest.fill(Infinity);
    const cu = at[k] % nu;
    const cv = (at[k] - cu) / nu;
    for (let gv = Math.max(0, cv - 2); gv <= Math.min(nv - 1, cv + 2); gv++) {
      for (let gu = Math.max(0, cu - 2); gu <= Math.min(nu - 1, cu + 2); gu++) {
        const c = gv * nu + gu;
        for (let s = start[c]; s < start[c + 1]; s++) {
          const j = order[s];
          if (j === k) continue;
          const du = u[j] - u[k];
          const dv = v[j] - v[k];
          const d2 = du * du + dv * dv;
          if (d2 > reach2) continue;
          const wedge = Math.abs(du) >= Math.abs(dv) ? (du > 0 ? 0 : 1) : (dv > 0 ? 2 : 3);
          if (d2 < nearest[wedge]) nearest[wedge] = d2;
        }
      }
    }
    let gap2 = 0;
    for (const d2 of nearest) if (d2 !== Infinity && d2 > gap2) gap2 = d2;
    const scale = Math.sqrt(gap2) / size;
    if (scale > 1) scales[members[k]] = scale;
  }
}
