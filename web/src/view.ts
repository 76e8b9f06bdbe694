// Where the photo sits on the canvas: screen = (image + 0.5) * scale + offset, in CSS pixels.
// Image points are (x, y) with the origin at the top-left pixel's centre (the engine's
// convention), so pixel (0, 0) covers [-0.5, 0.5] on both axes.

import type { Point } from "./types";

const MIN_SCALE = 0.02;
const MAX_SCALE = 64;

export class View {
  scale = 1;
  ox = 0;
  oy = 0;

  toScreen([x, y]: Point): Point {
    return [(x + 0.5) * this.scale + this.ox, (y + 0.5) * this.scale + this.oy];
  }

  toImage([sx, sy]: Point): Point {
    return [(sx - this.ox) / this.scale - 0.5, (sy - this.oy) / this.scale - 0.5];
  }

  /** Show the whole image, centred, in a canvas of (w, h) CSS pixels. */
  fit(imageW: number, imageH: number, w: number, h: number): void {
    this.scale = Math.min(w / imageW, h / imageH);
    this.ox = (w - imageW * this.scale) / 2;
    this.oy = (h - imageH * this.scale) / 2;
  }

  /** Zoom by `factor`, keeping the image point under screen position `at` where it is. */
  zoom(factor: number, at: Point): void {
    const before = this.toImage(at);
    this.scale = Math.min(MAX_SCALE, Math.max(MIN_SCALE, this.scale * factor));
    const after = this.toScreen(before);
    this.ox += at[0] - after[0];
    this.oy += at[1] - after[1];
  }

  pan(dx: number, dy: number): void {
    this.ox += dx;
    this.oy += dy;
  }
}

/** An image position rounded for display and for the job: 0.01 px is far below click precision. */
export function rounded([x, y]: Point): Point {
  return [Math.round(x * 100) / 100, Math.round(y * 100) / 100];
}

export function inside([x, y]: Point, w: number, h: number): boolean {
  return x >= -0.5 && y >= -0.5 && x <= w - 0.5 && y <= h - 0.5;
}
