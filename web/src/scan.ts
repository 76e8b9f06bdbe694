// The scan the user has set up, as one item of a job (the ScanSpec model with upload references),
// or a sentence saying what is still missing. A video's item has `frames` and `points`, or
// `frame_points` (per-frame points: exactly the frames marked are measured), or `points` with
// `points_frame` (the frame they were marked on: the service tracks them); several photos of
// one part are one item with `views`, measured as one box.

import { foundAsIs, pointsOrigin } from "./find-points";
import { inPart, partPhotos } from "./part";
import { describe, sequence, type Marks } from "./points";
import type { Settings } from "./settings";
import { allFrameMarks, photoShown, state, type PhotoEntry } from "./state";
import type { FrameSelection, PointSet, ScanSpec, VideoInfo, ViewSpec } from "./types";

export interface Scan {
  spec: ScanSpec;
  label: string;
}

/** The video's frame selection, given the frame the points were marked on. */
export type SelectFrames = (info: VideoInfo, marked: number | null) => FrameSelection;

export function hasMarks(): boolean {
  return Object.keys(state.marks).length > 0 || Object.keys(state.frameMarks).length > 0 || inPart();
}

function reference(which: "front" | "side"): { ref: string; name: string } {
  const photo = photoShown(which);
  if (!photo) throw new Error(`Choose the ${which} photo first.`);
  return uploaded(photo);
}

function uploaded(photo: PhotoEntry): { ref: string; name: string } {
  if (!photo.upload) {
    throw new Error(photo.status === "uploading…"
      ? `Wait for ${photo.name} to finish uploading.`
      : `${photo.name} was not uploaded (${photo.status}); add it again.`);
  }
  return { ref: photo.upload.reference, name: photo.name };
}

/** Every point asked for (`seven`: all seven, as a part's photo needs), in order; throws an Error
 *  naming the first one missing. */
function complete(marks: Marks, where = "", seven = false): PointSet {
  const names = sequence(seven || state.extra, state.twoPhoto);
  const missing = names.filter((n) => !marks[n]);
  if (missing.length) {
    const n = missing[0];
    throw new Error(`${where}${n.toUpperCase()} (${describe(n, state.twoPhoto)}) is not placed yet` +
      (seven ? "." : n === "p6" || n === "p7" ? "; place it, or untick P6 and P7." : "."));
  }
  return Object.fromEntries(names.map((n) => [n, marks[n]!]));
}

/** The current scan as a job item; throws an Error saying what to do when it is not ready. */
export function currentScan(settings: Settings, selectFrames: SelectFrames): Scan {
  if (inPart()) return partScan(settings);
  const front = reference("front");
  const video = photoShown("front")?.video;
  if (video) return videoScan(front, video.info, settings, selectFrames);
  const side = state.twoPhoto ? reference("side") : null;
  const asFound = side ? null : foundAsIs();
  if (asFound) {
    // The search tells the second face itself: the spec names none.
    const { side_face: _face, ...rest } = settings;
    const spec: ScanSpec = { image: front.ref, points: "auto", ...rest };
    if (asFound.hint) spec.auto_points = { hint: asFound.hint };
    return { spec, label: `${front.name} (${pointsOrigin()})` };
  }
  const spec: ScanSpec = { image: front.ref, points: complete(state.marks), ...settings };
  if (side) spec.side_image = side.ref;
  const origin = pointsOrigin();
  return { spec, label: side ? `${front.name} + ${side.name}` : origin ? `${front.name} (${origin})` : front.name };
}

function videoScan(front: { ref: string; name: string }, info: VideoInfo | null, settings: Settings,
                   selectFrames: SelectFrames): Scan {
  if (state.twoPhoto) throw new Error("A video is measured in single-photo mode: choose “One photo” under Mode.");
  if (!info) throw new Error(`Wait for the service to read ${front.name}.`);
  if (state.tracked) return trackedScan(front, info, settings, selectFrames);
  if (!state.perFrame) {
    const spec = { image: front.ref, points: complete(state.marks), frames: selectFrames(info, state.markedFrame) };
    const origin = pointsOrigin();
    return { spec: { ...spec, ...settings }, label: `${front.name} (video${origin ? `, ${origin}` : ""})` };
  }
  const marked = Object.entries(allFrameMarks()).sort(([a], [b]) => Number(a) - Number(b));
  if (!marked.length) throw new Error("Mark the points on at least one frame.");
  const framePoints = Object.fromEntries(marked.map(([f, marks]) => [f, complete(marks, `Frame ${f}: `)]));
  return {
    spec: { image: front.ref, frame_points: framePoints, ...settings },
    label: `${front.name} (video, frames ${marked.map(([f]) => f).join(", ")})`,
  };
}

/** The seven points of one frame, tracked by the service to the frames selected (`points_frame`);
 *  measured frame by frame, or as one box when asked. */
function trackedScan(front: { ref: string; name: string }, info: VideoInfo, settings: Settings,
                     selectFrames: SelectFrames): Scan {
  const marked = state.markedFrame;
  if (marked === null) throw new Error("Mark the seven points on one frame: the service tracks them to the others.");
  const points = complete(state.marks, `Frame ${marked}: `, true);
  const spec: ScanSpec = { image: front.ref, points, points_frame: marked, frames: selectFrames(info, marked), ...settings };
  const joint = (document.getElementById("track-joint") as HTMLInputElement).checked;
  if (joint) spec.fit = "joint";
  return { spec, label: `${front.name} (video, points of frame ${marked} tracked${joint ? ", one box" : ""})` };
}

/** The part's photos as one item with `views` (each its seven points, second face and file name),
 *  measured as one box; the settings' known edge, focal length and nominal size go with it. */
function partScan(settings: Settings): Scan {
  if (settings.method === "paper") {
    throw new Error("The paper's colour scan measures one photo: choose “Fitted edges” under Method to " +
      "measure several photos of one part as one box.");
  }
  const views: ViewSpec[] = partPhotos().map(({ photo, view }, k) => {
    if (!photo) throw new Error(`Photo ${k + 1} of this part is no longer listed: remove it from the part.`);
    const { ref, name } = uploaded(photo);
    const points = complete(view.marks, `Photo ${k + 1} of this part (${name}): `, true);
    return { image: ref, points, side_face: view.face, name: name.slice(0, 200) };
  });
  // No cloud is made: the cloud's settings (colour tolerance, method, cloud kind, outputs) do not
  // apply, and each view carries its own second face.
  const { tolerance: _t, method: _m, cloud: _c, side_face: _f, formats: _o, ...rest } = settings;
  return { spec: { views, ...rest }, label: `${views.length} photos of one part (${views.map((v) => v.name).join(", ")})` };
}
