// The magnifier: the pixels around the pointer, enlarged without smoothing, with a crosshair on
// the exact position a click would record. It follows the pointer, not the canvas's zoom.

import type { Point } from "./types";

const PIXELS_ACROSS = 22; // image pixels shown across the loupe

export function drawLoupe(canvas: HTMLCanvasElement, image: CanvasImageSource | null, at: Point | null,
                          marks: [string, Point][]): void {
  const ctx = canvas.getContext("2d")!;
  const size = canvas.width;
  ctx.clearRect(0, 0, size, size);
  canvas.hidden = image === null || at === null;
  if (image === null || at === null) return;
  const zoom = size / PIXELS_ACROSS;
  // Source rectangle in pixel-edge coordinates: image point x sits at pixel edge x + 0.5.
  const sx = at[0] + 0.5 - PIXELS_ACROSS / 2;
  const sy = at[1] + 0.5 - PIXELS_ACROSS / 2;
  ctx.imageSmoothingEnabled = false;
  ctx.fillStyle = "#222";
  ctx.fillRect(0, 0, size, size);
  ctx.save();
  ctx.scale(zoom, zoom);
  ctx.translate(-sx, -sy);
  ctx.drawImage(image, 0, 0);
  ctx.restore();
  ctx.strokeStyle = "rgba(255,255,255,0.9)";
  ctx.lineWidth = 1;
  for (const [name, p] of marks) {
    const x = (p[0] + 0.5 - sx) * zoom;
    const y = (p[1] + 0.5 - sy) * zoom;
    if (x < 0 || y < 0 || x > size || y > size) continue;
    ctx.strokeStyle = "#ffd400";
    ctx.strokeRect(x - 4, y - 4, 8, 8);
    ctx.fillStyle = "#ffd400";
    ctx.font = "11px sans-serif";
    ctx.fillText(name.toUpperCase(), x + 6, y - 6);
  }
  const c = size / 2;
  ctx.strokeStyle = "#ff2d55";
  ctx.beginPath();
  ctx.moveTo(c, 0);
  ctx.lineTo(c, c - 5);
  ctx.moveTo(c, c + 5);
  ctx.lineTo(c, size);
  ctx.moveTo(0, c);
  ctx.lineTo(c - 5, c);
  ctx.moveTo(c + 5, c);
  ctx.lineTo(size, c);
  ctx.stroke();
}
