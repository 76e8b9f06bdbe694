// What the photo canvas (marker.ts) asks of the page that hosts it, and what painting it
// (marker-draw.ts) reads: apart from both, so neither imports the other's module for it.

import type { Point, PointName } from "./types";

export interface MarkerHost {
  image(): ImageBitmap | null;
  marks(): [PointName, Point][]; // the points on the photo shown
  outlines(): Point[][];
  found(): Point[][]; // the faces the service's search found, drawn dashed under the outlines
  place(p: Point): void; // the next point goes here
  snapshot(): void; // before a drag or nudge, so undo can take it back
  move(name: PointName, p: Point): void;
  undo(): void;
  pointer(p: Point | null): void;
}
