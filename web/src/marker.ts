// The photo canvas: shows the photo being marked, its points and face outlines, and turns
// pointer and keyboard input into placing, dragging and nudging points, panning and zooming.

import { drawLoupe } from "./loupe";
import { drawMarker } from "./marker-draw";
import type { MarkerHost } from "./marker-host";
import type { Point, PointName } from "./types";
import { inside, rounded, View } from "./view";

const HIT_PX = 9; // a press this close to a point grabs it
const CLICK_SLOP_PX = 4; // a press that moves further than this pans instead of clicking

export class Marker {
  readonly view = new View();
  selected: PointName | null = null;
  private press: { at: Point; grabbed: PointName | null; panning: boolean; moved: boolean } | null = null;
  private hover: Point | null = null;
  loupeOn = true;

  constructor(private canvas: HTMLCanvasElement, private loupe: HTMLCanvasElement,
              private host: MarkerHost) {
    canvas.addEventListener("pointerdown", (e) => this.down(e));
    canvas.addEventListener("pointermove", (e) => this.moveTo(e));
    canvas.addEventListener("pointerup", (e) => this.up(e));
    canvas.addEventListener("pointerleave", () => this.leave());
    canvas.addEventListener("wheel", (e) => {
      e.preventDefault();
      this.zoom(Math.exp(-e.deltaY * 0.0015), this.local(e));
    }, { passive: false });
    canvas.addEventListener("keydown", (e) => this.key(e));
    new ResizeObserver(() => this.fit()).observe(canvas);
  }

  private local(e: MouseEvent): Point {
    const r = this.canvas.getBoundingClientRect();
    return [e.clientX - r.left, e.clientY - r.top];
  }

  fit(): void {
    const image = this.host.image();
    if (image) this.view.fit(image.width, image.height, this.canvas.clientWidth, this.canvas.clientHeight);
    this.draw();
  }

  zoom(factor: number, at?: Point): void {
    this.view.zoom(factor, at ?? [this.canvas.clientWidth / 2, this.canvas.clientHeight / 2]);
    this.draw();
  }

  private hit(at: Point): PointName | null {
    let best: PointName | null = null;
    let bestD = HIT_PX;
    for (const [name, p] of this.host.marks()) {
      const s = this.view.toScreen(p);
      const d = Math.hypot(s[0] - at[0], s[1] - at[1]);
      if (d <= bestD) [best, bestD] = [name, d];
    }
    return best;
  }

  private down(e: PointerEvent): void {
    if (e.button !== 0 || !this.host.image()) return;
    this.canvas.setPointerCapture(e.pointerId);
    const at = this.local(e);
    this.press = { at, grabbed: this.hit(at), panning: false, moved: false };
    if (this.press.grabbed) this.selected = this.press.grabbed;
  }

  private moveTo(e: PointerEvent): void {
    const at = this.local(e);
    const image = this.host.image();
    const p = this.view.toImage(at);
    this.hover = image && inside(p, image.width, image.height) ? rounded(p) : null;
    this.host.pointer(this.hover);
    const press = this.press;
    if (press?.grabbed && this.hover) {
      if (!press.moved) this.host.snapshot();
      press.moved = true;
      this.host.move(press.grabbed, this.hover);
    } else if (press && !press.grabbed) {
      const [dx, dy] = [at[0] - press.at[0], at[1] - press.at[1]];
      if (press.panning || Math.hypot(dx, dy) > CLICK_SLOP_PX) {
        press.panning = true;
        this.view.pan(dx, dy);
        press.at = at;
      }
    }
    this.draw();
  }

  private up(e: PointerEvent): void {
    const press = this.press;
    this.press = null;
    if (!press || press.panning || press.moved) return this.draw();
    if (press.grabbed) {
      // A click (not a drag) on a point puts the next point on the same spot: in one-photo
      // mode P4 is the corner that P2 already marks.
      const at = this.host.marks().find(([n]) => n === press.grabbed)?.[1];
      if (at) this.host.place(at);
      return this.draw();
    }
    const image = this.host.image()!;
    const p = this.view.toImage(this.local(e));
    if (inside(p, image.width, image.height)) this.host.place(rounded(p));
  }

  private leave(): void {
    this.hover = null;
    this.host.pointer(null);
    this.draw();
  }

  private key(e: KeyboardEvent): void {
    const step = e.shiftKey ? 10 : 1;
    const arrows: Record<string, Point> = {
      ArrowLeft: [-step, 0], ArrowRight: [step, 0], ArrowUp: [0, -step], ArrowDown: [0, step],
    };
    const image = this.host.image();
    const sel = this.host.marks().find(([n]) => n === this.selected);
    if (e.key in arrows && sel && image) {
      const [dx, dy] = arrows[e.key];
      const p: Point = [sel[1][0] + dx, sel[1][1] + dy];
      if (inside(p, image.width, image.height)) {
        this.host.snapshot();
        this.host.move(sel[0], rounded(p));
      }
    } else if (e.key === "+" || e.key === "=") this.zoom(1.25);
    else if (e.key === "-") this.zoom(0.8);
    else if (e.key === "0") this.fit();
    else if (e.key === "z" && (e.ctrlKey || e.metaKey)) this.host.undo();
    else return;
    e.preventDefault();
  }

  draw(): void {
    drawMarker(this.canvas, this.view, this.host, this.selected);
    this.canvas.dataset.view = `${this.view.scale},${this.view.ox},${this.view.oy}`;
    drawLoupe(this.loupe, this.loupeOn ? this.host.image() : null, this.hover, this.host.marks());
  }
}
