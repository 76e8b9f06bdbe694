// Several photos of one part, measured as ONE box (a job item's `views`): which photos, in the
// order they were added, and each one's points and second face. The photo shown is the front
// photo and its points are `state.marks`, as for one photo (the canvas, undo and the table of
// points work unchanged); the others' are kept in `state.partViews` until shown again. With no
// part (state.part empty), one photo is measured alone, as before.

import { faceChoice, sequence, setFaceChoice, type Marks } from "./points";
import { state, type PartView, type PhotoEntry } from "./state";

/** The most photos of one part the page marks (the service takes up to 24): each is marked by
 *  hand, and a few views from well apart give the fit most of what it gains. */
export const PART_MAX = 6;

export function inPart(): boolean {
  return state.part.length > 0;
}

/** Are all seven points, which a photo of a part needs, placed? */
export function sevenPlaced(marks: Marks): boolean {
  return sequence(true).every((n) => marks[n]);
}

/** The part's photos in order, each with its points and second face (the shown one's as they are now). */
export function partPhotos(): { id: number; photo: PhotoEntry | null; view: PartView }[] {
  return state.part.map((id) => ({
    id,
    photo: state.photos.find((p) => p.id === id) ?? null,
    view: id === state.partShown ? { marks: state.marks, face: faceChoice() } : state.partViews[id],
  }));
}

/** Keep the photo shown (its points, its second face) in the part and show photo `next`, added
 *  to the part when new. The first call makes the photo shown the part's first. */
export function showInPart(next: number): void {
  const shown = state.partShown ?? state.front;
  if (shown === null || shown === next) return;
  if (!state.part.includes(shown)) state.part.push(shown);
  state.partViews[shown] = { marks: state.marks, face: faceChoice() };
  const view = state.partViews[next] ?? { marks: {}, face: "auto" };
  delete state.partViews[next];
  if (!state.part.includes(next)) state.part.push(next);
  state.partShown = next;
  state.front = next;
  state.marks = view.marks;
  setFaceChoice(view.face);
  state.undoStack = [];
  state.markedFrame = null;
}

/** Take photo `id` out of the part (its upload stays in the list of photos). One photo left: it
 *  is shown with its points and measured alone again. */
export function removeFromPart(id: number): void {
  const at = state.part.indexOf(id);
  if (at < 0) return;
  if (id === state.partShown) showInPart(state.part[at - 1] ?? state.part[at + 1]);
  state.part.splice(at, 1);
  delete state.partViews[id];
  if (state.part.length < 2) {
    state.part = [];
    state.partViews = {};
    state.partShown = null;
  }
}

/** The line before the next point's prompt: which photo of the part is shown, and what to mark. */
export function partPrompt(): string {
  if (!inPart() || state.partShown === null) return "";
  const k = state.part.indexOf(state.partShown) + 1;
  const name = state.photos.find((p) => p.id === state.partShown)?.name ?? "";
  return `Photo ${k} of ${state.part.length} of this part (${name})` +
    (k > 1 ? ": mark the same front face as on photo 1, with P1 on the same corner. " : ". ");
}
