// Step 2 of the page: the photo canvas and everything around it (the prompt for the next point,
// the photo switch, undo and clear, the pointer readout and the table of points).

import { foundFaces } from "./find-points";
import { Marker } from "./marker";
import { partPrompt } from "./part";
import { renderPointTable } from "./point-table";
import { describe, photoOf, regions, setFaceChoice, type FaceChoice, type Photo } from "./points";
import * as S from "./state";
import type { Point, PointName } from "./types";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;

export class Marking {
  readonly marker: Marker;
  onChange: () => void = () => {};

  constructor(private paperMethod: () => boolean) {
    this.marker = new Marker($("marker"), $("loupe"), {
      image: () => S.photoShown()?.bitmap ?? null,
      marks: () => S.marksOn(S.state.shown),
      outlines: () => this.outlines(),
      found: () => foundFaces(),
      place: (p) => this.place(p),
      snapshot: () => S.snapshot(),
      move: (name, p) => this.changed(() => S.move(name, p)),
      undo: () => this.changed(S.undo),
      pointer: (p) => this.pointer(p),
    });
    $("undo").addEventListener("click", () => this.changed(S.undo));
    $("clear").addEventListener("click", () => this.changed(() => S.clear()));
    $("show-front").addEventListener("click", () => this.show("front"));
    $("show-side").addEventListener("click", () => this.show("side"));
    $("zoom-in").addEventListener("click", () => this.marker.zoom(1.25));
    $("zoom-out").addEventListener("click", () => this.marker.zoom(0.8));
    $("zoom-fit").addEventListener("click", () => this.marker.fit());
    $<HTMLInputElement>("loupe-on").addEventListener("change", (e) => {
      this.marker.loupeOn = (e.target as HTMLInputElement).checked;
      this.marker.draw();
    });
    $<HTMLInputElement>("extra-corners").addEventListener("change", (e) => {
      S.state.extra = (e.target as HTMLInputElement).checked;
      this.changed(() => (S.state.extra ? undefined : S.clear(["p6", "p7"])));
    });
    $<HTMLSelectElement>("second-face").addEventListener("change", (e) => {
      setFaceChoice((e.target as HTMLSelectElement).value as FaceChoice);
      this.changed(() => {});
    });
  }

  private outlines(): Point[][] {
    const r = regions(S.state.marks, S.state.twoPhoto, this.paperMethod());
    const faces: Photo[] = ["front", "side"];
    return faces.map((f) => (photoOf(f === "front" ? "p1" : "p4", S.state.twoPhoto) === S.state.shown
      ? r[f] : undefined)).filter((q): q is Point[] => q !== undefined);
  }

  private place(p: Point): void {
    const name = S.nextPoint();
    if (!name || photoOf(name, S.state.twoPhoto) !== S.state.shown) return;
    this.marker.selected = name;
    this.changed(() => S.place(name, p));
  }

  private pointer(p: Point | null): void {
    $("pointer-xy").textContent = p ? `x ${p[0].toFixed(1)}, y ${p[1].toFixed(1)}` : "x –, y –";
  }

  show(which: Photo): void {
    S.state.shown = which;
    $("show-front").setAttribute("aria-pressed", String(which === "front"));
    $("show-side").setAttribute("aria-pressed", String(which === "side"));
    this.marker.fit();
    this.refresh();
  }

  /** Apply a change to the points, then bring every view of them up to date. */
  changed(change: () => void): void {
    change();
    const next = S.nextPoint();
    // The next point lives on the other photo (two-photo mode): go there.
    if (next && photoOf(next, S.state.twoPhoto) !== S.state.shown && S.photoShown(photoOf(next, true))) {
      this.show(photoOf(next, S.state.twoPhoto));
    }
    this.refresh();
    this.onChange();
  }

  refresh(): void {
    const next: PointName | null = S.nextPoint();
    const two = S.state.twoPhoto;
    $("show-side").hidden = !two;
    $("second-face-row").hidden = two; // a side photo shows the side face
    let prompt = "Every point is placed. Drag a point, or use the arrow keys, to adjust it.";
    if (!S.photoShown("front")) prompt = "Add a photo or a video to start.";
    else if (next && two && !S.photoShown("side") && photoOf(next, true) === "side") {
      prompt = `Choose the side photo, then click ${next.toUpperCase()}: ${describe(next, two)}.`;
    } else if (next) prompt = `Click ${next.toUpperCase()}: ${describe(next, two)}.`;
    $("next-point").textContent = partPrompt() + prompt;
    renderPointTable((name, p) => this.changed(() => S.place(name, p)));
    this.marker.draw();
  }
}
