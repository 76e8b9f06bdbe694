// What the user has set up so far: the photos, the mode, the points; one object, read by the
// modules that draw it, changed only through the functions here so undo sees every change.

import { photoOf, sequence, type FaceChoice, type Marks, type Photo } from "./points";
import type { Point, PointName, Upload, VideoInfo } from "./types";

export interface PhotoEntry {
  id: number;
  name: string;
  bitmap: ImageBitmap | null; // a video's: the frame shown
  upload: Upload | null;
  status: string;
  video: { info: VideoInfo | null; frame: number } | null; // null for a photo
}

/** A photo of a part measured as one box, while another is shown: its points and second face. */
export interface PartView {
  marks: Marks;
  face: FaceChoice;
}

export const state = {
  photos: [] as PhotoEntry[],
  twoPhoto: false,
  extra: true, // seven points: perspective corrected (five is the paper's square-on model)
  front: null as number | null, // photo ids
  side: null as number | null,
  shown: "front" as Photo,
  marks: {} as Marks, // a video's: on the frame shown
  undoStack: [] as Marks[],
  // Videos: each frame's own points (the frame shown's are in `marks`), or the same points for
  // every frame; and the frame last marked on.
  perFrame: false,
  // Or the points of the frame marked, tracked by the service to the frames measured (points_frame).
  tracked: false,
  frameMarks: {} as Record<number, Marks>,
  markedFrame: null as number | null,
  // Several photos of one part, measured as one box (part.ts): their ids in order, the one whose
  // points are in `marks` (the front photo), and the others' points. Empty: one photo alone.
  part: [] as number[],
  partShown: null as number | null,
  partViews: {} as Record<number, PartView>,
};

/** The frame shown when the front "photo" is a video, else null. */
export function frameShown(): number | null {
  return photoShown("front")?.video?.frame ?? null;
}

export function photoShown(which: Photo = state.shown): PhotoEntry | null {
  const id = which === "front" ? state.front : state.side;
  return state.photos.find((p) => p.id === id) ?? null;
}

/** The next point to click, or null when every point asked for is placed. */
export function nextPoint(): PointName | null {
  return sequence(state.extra, state.twoPhoto).find((n) => !state.marks[n]) ?? null;
}

export function snapshot(): void {
  state.undoStack.push({ ...state.marks });
  if (state.undoStack.length > 200) state.undoStack.shift();
}

export function place(name: PointName, p: Point): void {
  snapshot();
  move(name, p);
}

/** Every point at once (found by the service), undoable as one change. */
export function placeAll(marks: Marks): void {
  snapshot();
  state.marks = { ...marks };
  state.markedFrame = frameShown();
}

export function move(name: PointName, p: Point): void {
  state.marks = { ...state.marks, [name]: p };
  state.markedFrame = frameShown();
}

/** Per-frame points: keep the frame shown's points, and bring out frame `next`'s. */
export function switchFrame(shown: number, next: number): void {
  if (Object.keys(state.marks).length) state.frameMarks[shown] = state.marks;
  else delete state.frameMarks[shown];
  state.marks = state.frameMarks[next] ?? {};
  delete state.frameMarks[next];
  state.undoStack = [];
}

/** Every frame's points (per-frame mode), the frame shown's included. */
export function allFrameMarks(): Record<number, Marks> {
  const all: Record<number, Marks> = { ...state.frameMarks };
  const shown = frameShown();
  if (shown !== null && Object.keys(state.marks).length) all[shown] = state.marks;
  return all;
}

export function undo(): void {
  const previous = state.undoStack.pop();
  if (previous) state.marks = previous;
}

export function clear(names?: PointName[]): void {
  snapshot();
  if (!names) state.marks = {};
  else state.marks = Object.fromEntries(Object.entries(state.marks).filter(([n]) => !names.includes(n as PointName)));
}

/** Forget every point, every frame's and every photo of a part's included (another video, or a
 *  scan added to the batch). */
export function clearAll(): void {
  clear();
  state.frameMarks = {};
  state.markedFrame = null;
  state.part = [];
  state.partShown = null;
  state.partViews = {};
}

/** The points marked on one photo, in click order. */
export function marksOn(which: Photo): [PointName, Point][] {
  return sequence(true)
    .filter((n) => state.marks[n] && photoOf(n, state.twoPhoto) === which)
    .map((n) => [n, state.marks[n]!]);
}
