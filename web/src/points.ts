// The reference points, the order they are clicked in, and the face regions they outline
// (mirrors prismcore.geometry.faces.clicked_quads, paper_rectangles and resolve_side_face, so what is
// drawn is what is scanned).
//
// P1, P2, P3 (and P6) are the front's corners. P4, P5 (and P7) mark the second face by role: P4
// is the front corner where the second face's top (far) edge starts, P5 the second face's far
// corner next to P4, P7 its far corner next to the other shared corner. In one photo the second
// face is the right side (P4 = P2), the left side (P4 = P1, P5 left of it) or the top (P4 = P1,
// P5 above it); a side photo shows a right side.

import type { Point, PointName } from "./types";

export type Photo = "front" | "side";
export type SecondFace = "right" | "left" | "top";
export type FaceChoice = SecondFace | "auto";

export const POINTS: Record<PointName, { where: string; face: Photo }> = {
  p1: { where: "front face, upper-left corner", face: "front" },
  p2: { where: "front face, upper-right corner", face: "front" },
  p3: { where: "front face, lower-right corner", face: "front" },
  p4: { where: "side face, upper-left corner", face: "side" },
  p5: { where: "side face, upper-right corner", face: "side" },
  p6: { where: "front face, lower-left corner (optional)", face: "front" },
  p7: { where: "side face, lower-right corner (optional)", face: "side" },
};

/** One photo: where P4, P5 and P7 are for each second face. */
const SECOND: Record<FaceChoice, Partial<Record<PointName, string>>> = {
  right: {
    p4: "right side face, upper-left corner: the same corner as P2, so click P2",
    p5: "right side face, far upper corner (right of P2)",
    p7: "right side face, far lower corner (optional)",
  },
  left: {
    p4: "left side face, upper-right corner: the same corner as P1, so click P1",
    p5: "left side face, far upper corner (left of P1)",
    p7: "left side face, far lower corner, left of P6 (optional)",
  },
  top: {
    p4: "top face, lower-left corner: the same corner as P1, so click P1",
    p5: "top face, far corner above P1",
    p7: "top face, far corner above P2 (optional)",
  },
  auto: {
    p4: "where the second face starts: the same corner as P2 for a right side face (click P2), " +
      "or as P1 for a left side face or the top (click P1)",
    p5: "second face, its far corner next to P4 (right of P2, left of P1, or above P1)",
    p7: "second face, its other far corner (optional)",
  },
};

let choice: FaceChoice = "auto";

/** The second face chosen on the page ("auto": read from the points). */
export function faceChoice(): FaceChoice {
  return choice;
}

export function setFaceChoice(c: FaceChoice): void {
  choice = c;
}

/** The order the points are clicked in: the paper's, or with two photos each photo's in turn. */
export function sequence(extra: boolean, twoPhoto = false): PointName[] {
  if (!extra) return ["p1", "p2", "p3", "p4", "p5"];
  return twoPhoto ? ["p1", "p2", "p3", "p6", "p4", "p5", "p7"] : ["p1", "p2", "p3", "p4", "p5", "p6", "p7"];
}

/** The photo a point is marked on: in one-photo mode all of them are on the front photo. */
export function photoOf(name: PointName, twoPhoto: boolean): Photo {
  return twoPhoto ? POINTS[name].face : "front";
}

export type Marks = Partial<Record<PointName, Point>>;

const add = (a: Point, b: Point): Point => [a[0] + b[0], a[1] + b[1]];
const sub = (a: Point, b: Point): Point => [a[0] - b[0], a[1] - b[1]];
const dist = (a: Point, b: Point): number => Math.hypot(a[0] - b[0], a[1] - b[1]);
const SAME_CORNER = 0.5; // prismcore.geometry.faces._SAME_CORNER

/** (a, b) with v = a * across + b * down, each scaled by its axis' length (faces._front_axes). */
function inFront(v: Point, across: Point, down: Point): [number, number] {
  const det = across[0] * down[1] - across[1] * down[0];
  const a = (v[0] * down[1] - v[1] * down[0]) / det;
  const b = (across[0] * v[1] - across[1] * v[0]) / det;
  return [a * Math.hypot(...across), b * Math.hypot(...down)];
}

/** The second face the points mark in one photo (prismcore.geometry.faces.resolve_side_face), or null
 *  while they do not tell yet (or do not fit the choice). */
export function secondFace(m: Marks, twoPhoto: boolean, chosen: FaceChoice = choice): SecondFace | null {
  if (twoPhoto) return "right";
  const { p1, p2, p3, p4, p5, p6, p7 } = m;
  if (!p1 || !p2 || !p3 || !p4) return chosen === "auto" ? null : chosen;
  const [d1, d2] = [dist(p4, p1), dist(p4, p2)];
  let found: SecondFace | null = null;
  if (d2 < SAME_CORNER * d1) found = "right";
  else if (d1 < SAME_CORNER * d2) {
    if (!p5) return chosen === "auto" ? null : chosen;
    const across = sub(p2, p1);
    const down = sub(p6 ?? add(p1, sub(p3, p2)), p1);
    const [a, b] = inFront(sub(p5, p4), across, down);
    if (p7) {
      const [a7, b7] = inFront(sub(p7, p5), across, down);
      if (Math.abs(b7) > Math.abs(a7)) found = b7 > 0 && a < 0 ? "left" : null;
      else found = a7 > 0 && b < 0 ? "top" : null;
    } else if (a < 0 && Math.abs(a) > Math.abs(b)) found = "left";
    else if (b < 0 && Math.abs(b) >= Math.abs(a)) found = "top";
  }
  if (chosen !== "auto") return found === chosen ? chosen : null;
  return found;
}

/** Front and side outlines (top-left, top-right, bottom-right, bottom-left), as far as known. */
export function regions(m: Marks, twoPhoto: boolean, paper: boolean, chosen: FaceChoice = choice):
    { front?: Point[]; side?: Point[] } {
  const out: { front?: Point[]; side?: Point[] } = {};
  const { p1, p2, p3, p4, p5, p6, p7 } = m;
  if (p1 && p2 && p3) {
    out.front = paper
      ? [[p1[0], p1[1]], [p2[0], p1[1]], [p2[0], p3[1]], [p1[0], p3[1]]]
      : [p1, p2, p3, p6 ?? add(p1, sub(p3, p2))];
  }
  const face = secondFace(m, twoPhoto, chosen);
  if (!twoPhoto && p1 && p2 && p3 && p4 && p5 && (face === "left" || face === "top")) {
    if (paper) {
      out.side = face === "left"
        ? [[p5[0], p4[1]], [p4[0], p4[1]], [p4[0], p3[1]], [p5[0], p3[1]]]
        : [[p4[0], p5[1]], [p2[0], p5[1]], [p2[0], p4[1]], [p4[0], p4[1]]];
      return out;
    }
    if (face === "left") {
      const br = add(p6 ?? add(p1, sub(p3, p2)), sub(p4, p1));
      out.side = [p5, p4, br, p7 ?? add(p5, sub(br, p4))];
    } else {
      const br = add(p2, sub(p4, p1));
      out.side = [p5, p7 ?? add(p5, sub(br, p4)), br, p4];
    }
    return out;
  }
  if (!twoPhoto && face !== "right") return out; // not told yet which face P4 and P5 mark
  const known = twoPhoto ? p7 || (p1 && p2 && p3) : p2 && p3;
  if (p4 && p5 && known) {
    const frontHeight = p1 && p2 && p3 ? { paper: p3[1] - p1[1], fitted: dist(p3, p2) } : undefined;
    if (paper) {
      const bottom = !twoPhoto ? p3![1] : p7 ? p7[1] : p4[1] + frontHeight!.paper;
      out.side = [[p4[0], p4[1]], [p5[0], p4[1]], [p5[0], bottom], [p4[0], bottom]];
      return out;
    }
    let bl: Point;
    if (!twoPhoto) bl = add(p3!, sub(p4, p2!));
    else if (p7) bl = add(p4, sub(p7, p5));
    else bl = add(p4, [0, frontHeight!.fitted]);
    out.side = [p4, p5, p7 ?? add(p5, sub(bl, p4)), bl];
  }
  return out;
}

/** Where a point is, in words: in one-photo mode P4, P5 and P7 by the second face chosen (P4
 *  is the corner P2 or P1 already marks). */
export function describe(name: PointName, twoPhoto: boolean, chosen: FaceChoice = choice): string {
  if (!twoPhoto && SECOND[chosen][name]) return SECOND[chosen][name]!;
  return POINTS[name].where;
}
