// Step 2's "Find points": the service's zero-click search (GET /v1/uploads/{id}/points, run by a
// worker with the engine's prismcore.locate.search on the photo as a job decodes it) places P1...P7 for
// the person to check and drag, and the faces it found are drawn dashed on the photo; when it
// refuses, its reason is shown in words. With P1 placed, the search looks for the box under it
// (a hint), which settles a photo with two boxes. A photo's scan whose found points were not
// dragged is sent as points "auto" (see foundAsIs), so its results say the points were found.

import { message, whenReady } from "./api";
import { inPart } from "./part";
import { faceChoice, setFaceChoice, type Marks } from "./points";
import * as S from "./state";
import type { FoundPoints, Point, PointName } from "./types";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;

interface Placed {
  photo: number | null;
  frame: number | null;
  hint: Point | null; // as searched (whole px)
  marks: Marks;
  face: string; // the second face the search found (a person may choose another)
  faces: Point[][];
}

let placed: Placed | null = null; // the search's last answer placed on the page

/** Are the points shown the ones found (dragged or not), on the photo (frame) they were found in? */
function shown(): Placed | null {
  if (!placed || placed.photo !== S.state.front || placed.frame !== S.frameShown()) return null;
  if (S.state.shown !== "front" || !Object.keys(S.state.marks).length) return null;
  return placed;
}

/** The faces found, to draw while their photo (frame) and its points are shown. */
export function foundFaces(): Point[][] {
  return shown()?.faces ?? [];
}

function moved(found: Placed): boolean {
  if (faceChoice() !== found.face) return true; // the person corrected the second face
  return Object.keys({ ...found.marks, ...S.state.marks }).some((n) => {
    const [a, b] = [found.marks[n as PointName], S.state.marks[n as PointName]];
    return !a || !b || a[0] !== b[0] || a[1] !== b[1];
  });
}

/** How the scan's points came about, for its label in the batch: "" when clicked. */
export function pointsOrigin(): string {
  const found = shown();
  if (!found) return "";
  return moved(found) ? "points found, then adjusted" : "points found";
}

/** A photo's found points, as found (not dragged): the job item may say "auto" with the same
 *  hint, so the worker finds them again (the same search on the same decoded photo) and the
 *  results say the points were found, with the confidence. Null otherwise: the item gives the
 *  points as they are on the page (a person's check is then a click). */
export function foundAsIs(): { hint: Point | null } | null {
  const found = shown();
  return found && found.frame === null && !moved(found) ? { hint: found.hint } : null;
}

function sentence(text: string): string {
  return text.charAt(0).toUpperCase() + text.slice(1) + (/[.!?]$/.test(text) ? "" : ".");
}

export class FindPoints {
  /** `apply` makes a change to the points and brings every view of them up to date. */
  constructor(private apply: (change: () => void) => void) {
    $("find-points").addEventListener("click", () => void this.find());
  }

  /** Only one photo (or a video's frame) is searched: not in two-photo mode. */
  render(): void {
    $("find-row").hidden = S.state.twoPhoto;
  }

  private async find(): Promise<void> {
    const status = $("find-status");
    const button = $<HTMLButtonElement>("find-points");
    const photo = S.photoShown("front");
    if (!photo?.upload) {
      status.textContent = photo ? `Wait for ${photo.name} to finish uploading.` : "Add a photo first.";
      return;
    }
    const frame = S.frameShown();
    const p1 = S.state.marks.p1;
    const hint: Point | null = p1 ? [Math.round(p1[0]), Math.round(p1[1])] : null;
    const query = new URLSearchParams();
    if (hint) query.set("hint", `${hint[0]},${hint[1]}`);
    if (frame !== null) query.set("frame", String(frame));
    const path = `/v1/uploads/${photo.upload.id}/points${query.toString() ? `?${query}` : ""}`;
    button.disabled = true;
    status.textContent = hint ? "Looking for the box under P1…" : "Looking for the box in the photo…";
    let found: FoundPoints;
    try {
      const answer = await whenReady(path, "The service has not finished looking for the box; try again in a while.");
      found = (await answer.json()) as FoundPoints;
    } catch (err) {
      status.textContent = `Could not look for the box: ${message(err)}`;
      return;
    } finally {
      button.disabled = false;
    }
    if (S.photoShown("front") !== photo || S.frameShown() !== frame) {
      status.textContent = "The photo changed while the service looked for the box: press Find points again.";
      return;
    }
    if (!found.points || !found.side_face) {
      placed = null;
      const next = hint ? "Click the points yourself."
        : "Click P1 on the box you want and press Find points again to look there, or click the points yourself.";
      status.textContent = `No points placed. ${sentence(found.reason ?? "no box found")} ${next}`;
      this.apply(() => {});
      return;
    }
    const marks = found.points;
    const face = found.side_face;
    this.apply(() => {
      // A part's photo keeps all seven points asked for (part.ts).
      S.state.extra = inPart() || Boolean(marks.p6 && marks.p7);
      $<HTMLInputElement>("extra-corners").checked = S.state.extra;
      setFaceChoice(face);
      $<HTMLSelectElement>("second-face").value = face;
      S.placeAll(marks);
      placed = { photo: S.state.front, frame, hint, marks: { ...marks }, face, faces: found.faces };
    });
    const warned = found.warnings.length ? ` ${found.warnings.map(sentence).join(" ")}` : "";
    status.textContent = `Found the box (confidence ${found.confidence.toFixed(2)}, second face: ` +
      `${face}): check the points and drag any that are off.${warned}`;
  }
}
