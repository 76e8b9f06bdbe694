// Painting the photo canvas: the photo at the view's zoom, the faces the service found (dashed),
// the face outlines, and each point as a crosshair with its label (P1...P7) on a dark tab so it
// reads on any photo.

import type { MarkerHost } from "./marker-host";
import type { Point, PointName } from "./types";
import type { View } from "./view";

const OUTLINE_COLOURS = ["rgba(0, 200, 255, 0.95)", "rgba(255, 140, 0, 0.95)"];
const FILL_COLOURS = ["rgba(0, 200, 255, 0.14)", "rgba(255, 140, 0, 0.14)"];
const FOUND_COLOUR = "rgba(60, 255, 120, 0.95)";

export function drawMarker(canvas: HTMLCanvasElement, view: View, host: MarkerHost,
                           selected: PointName | null): void {
  const dpr = window.devicePixelRatio || 1;
  const [w, h] = [canvas.clientWidth, canvas.clientHeight];
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
  }
  const ctx = canvas.getContext("2d")!;
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.fillStyle = "#30343a";
  ctx.fillRect(0, 0, w, h);
  const image = host.image();
  if (!image) {
    ctx.fillStyle = "#ddd";
    ctx.font = "16px sans-serif";
    ctx.fillText("Add a photo or a video above to start marking.", 20, 32);
    return;
  }
  // Past 2x the pixels are shown as squares, so a corner can be put on the right one.
  ctx.imageSmoothingEnabled = view.scale < 2;
  ctx.drawImage(image, view.ox, view.oy, image.width * view.scale, image.height * view.scale);
  host.found().forEach((quad) => dashed(ctx, view, quad));
  host.outlines().forEach((quad, i) => outline(ctx, view, quad, i));
  for (const [name, p] of host.marks()) mark(ctx, view.toScreen(p), name, name === selected);
}

function outline(ctx: CanvasRenderingContext2D, view: View, quad: Point[], i: number): void {
  ctx.beginPath();
  quad.map((p) => view.toScreen(p)).forEach(([x, y], k) => (k ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
  ctx.closePath();
  ctx.fillStyle = FILL_COLOURS[i % 2];
  ctx.fill();
  ctx.strokeStyle = OUTLINE_COLOURS[i % 2];
  ctx.lineWidth = 1.5;
  ctx.stroke();
}

function dashed(ctx: CanvasRenderingContext2D, view: View, quad: Point[]): void {
  ctx.beginPath();
  quad.map((p) => view.toScreen(p)).forEach(([x, y], k) => (k ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
  ctx.closePath();
  ctx.setLineDash([6, 4]);
  ctx.strokeStyle = FOUND_COLOUR;
  ctx.lineWidth = 2;
  ctx.stroke();
  ctx.setLineDash([]);
}

function mark(ctx: CanvasRenderingContext2D, [x, y]: Point, name: string, selected: boolean): void {
  ctx.strokeStyle = selected ? "#ff2d55" : "#ffd400";
  ctx.lineWidth = selected ? 2 : 1.5;
  ctx.beginPath();
  ctx.moveTo(x - 9, y);
  ctx.lineTo(x - 3, y);
  ctx.moveTo(x + 3, y);
  ctx.lineTo(x + 9, y);
  ctx.moveTo(x, y - 9);
  ctx.lineTo(x, y - 3);
  ctx.moveTo(x, y + 3);
  ctx.lineTo(x, y + 9);
  ctx.stroke();
  const label = name.toUpperCase();
  ctx.font = "bold 13px sans-serif";
  const tw = ctx.measureText(label).width;
  ctx.fillStyle = "rgba(0, 0, 0, 0.75)";
  ctx.fillRect(x + 8, y - 24, tw + 8, 18);
  ctx.fillStyle = selected ? "#ff8fa6" : "#ffd400";
  ctx.fillText(label, x + 12, y - 10);
}
