// The reference points, the order they are clicked in, and the face regions they outline
// (mirrors prismcore.faces.clicked_quads and paper_rectangles, so what is drawn is what is scanned).

import type { Point, PointName } from "./types";

export type Photo = "front" | "side";

export const POINTS: Record<PointName, { where: string; face: Photo }> = {
  p1: { where: "front face, upper-left corner", face: "front" },
  p2: { where: "front face, upper-right corner", face: "front" },
  p3: { where: "front face, lower-right corner", face: "front" },
  p4: { where: "side face, upper-left corner", face: "side" },
  p5: { where: "side face, upper-right corner", face: "side" },
  p6: { where: "front face, lower-left corner (optional)", face: "front" },
  p7: { where: "side face, lower-right corner (optional)", face: "side" },
};

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

/** Front and side outlines (top-left, top-right, bottom-right, bottom-left), as far as known. */
export function regions(m: Marks, twoPhoto: boolean, paper: boolean): { front?: Point[]; side?: Point[] } {
  const out: { front?: Point[]; side?: Point[] } = {};
  const { p1, p2, p3, p4, p5, p6, p7 } = m;
  if (p1 && p2 && p3) {
    out.front = paper
      ? [[p1[0], p1[1]], [p2[0], p1[1]], [p2[0], p3[1]], [p1[0], p3[1]]]
      : [p1, p2, p3, p6 ?? add(p1, sub(p3, p2))];
  }
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

/** Where a point is, in words; in one-photo mode P4 is the corner P2 already marks. */
export function describe(name: PointName, twoPhoto: boolean): string {
  return name === "p4" && !twoPhoto ? "side face, upper-left corner: the same corner as P2, so click P2"
    : POINTS[name].where;
}
