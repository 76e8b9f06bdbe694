// Point colours for the 3D view: the photo's own, or a colour ramp over depth (Z) or height (Y)
// that shows the shape where the photo's colours are flat.

import * as THREE from "three";

export type ColourMode = "photo" | "depth" | "height";

// A perceptually even ramp (viridis, five stops), dark for small values.
const RAMP = [[0.267, 0.005, 0.329], [0.229, 0.322, 0.546], [0.128, 0.567, 0.551],
  [0.369, 0.789, 0.383], [0.993, 0.906, 0.144]];

function ramp(t: number, out: THREE.Color): THREE.Color {
  const x = Math.min(Math.max(t, 0), 1) * (RAMP.length - 1);
  const i = Math.min(Math.floor(x), RAMP.length - 2);
  const f = x - i;
  const [a, b] = [RAMP[i], RAMP[i + 1]];
  return out.setRGB(a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]),
    THREE.SRGBColorSpace);
}

/** The colour attribute for `mode`; the photo colours are kept aside the first time. */
export function colours(geometry: THREE.BufferGeometry, mode: ColourMode): THREE.BufferAttribute {
  const position = geometry.getAttribute("position");
  const count = position.count;
  if (!geometry.userData.photo) {
    const given = geometry.getAttribute("color") as THREE.BufferAttribute | undefined;
    // A cloud without colours shows in light grey rather than black.
    geometry.userData.photo = given ?? new THREE.BufferAttribute(new Float32Array(count * 3).fill(0.8), 3);
  }
  if (mode === "photo") return geometry.userData.photo as THREE.BufferAttribute;
  const axis = mode === "depth" ? 2 : 1;
  let lo = Infinity;
  let hi = -Infinity;
  for (let i = 0; i < count; i++) {
    const v = position.getComponent(i, axis);
    lo = Math.min(lo, v);
    hi = Math.max(hi, v);
  }
  const span = hi > lo ? hi - lo : 1;
  const out = new Float32Array(count * 3);
  const c = new THREE.Color();
  for (let i = 0; i < count; i++) {
    // Height: Y grows downwards in the box frame, so the top of the part gets the bright end.
    const t = (position.getComponent(i, axis) - lo) / span;
    ramp(mode === "height" ? 1 - t : t, c);
    out.set([c.r, c.g, c.b], i * 3);
  }
  return new THREE.BufferAttribute(out, 3);
}
