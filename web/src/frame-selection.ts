// Step 3 for a video: which frames are measured (the spec's `frames`) and whether the points hold
// for every frame (`points`), only for the frames marked, each its own (`frame_points`), or are
// tracked by the service from the frame marked to the others (`points_frame`).
// The candidates mirror prismcore.video.frame_select, so the note says which frames will be measured.

import { state } from "./state";
import type { FrameSelection, VideoInfo } from "./types";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
const value = (id: string) => $<HTMLInputElement | HTMLSelectElement>(id).value.trim();

export class FrameSelectionForm {
  onModeChange: () => void = () => {};

  constructor(private info: () => VideoInfo | null) {
    for (const radio of document.querySelectorAll<HTMLInputElement>("input[name=frame-points]")) {
      radio.addEventListener("change", () => {
        if (!radio.checked) return;
        state.perFrame = radio.value === "each";
        state.tracked = radio.value === "track";
        this.render();
        this.onModeChange();
      });
    }
    for (const id of ["select-kind", "select-every", "select-indices", "select-sharpest", "select-start", "select-end"]) {
      $(id).addEventListener("input", () => this.render());
    }
  }

  /** Show the fields of the chosen kind and say what will be measured. */
  render(): void {
    const info = this.info();
    $("video-settings").hidden = info === null;
    if (!info) return;
    const kind = value("select-kind");
    $("frame-selection").hidden = state.perFrame;
    $("track-options").hidden = !state.tracked;
    for (const el of document.querySelectorAll<HTMLElement>("#frame-selection [data-kind]")) {
      el.hidden = !el.dataset.kind!.split(" ").includes(kind);
    }
    let note: string;
    try {
      note = this.describe(info);
    } catch (err) {
      note = (err as Error).message;
    }
    $("selection-note").textContent = note;
  }

  private describe(info: VideoInfo): string {
    if (state.perFrame) {
      return "Exactly the frames you mark are measured, each with its own points; the frame slider " +
        "keeps each frame's points.";
    }
    const selection = this.read(info, state.markedFrame);
    const tracked = state.tracked ? (state.markedFrame === null
      ? " Mark the seven points on one frame: they are tracked from it to each frame measured."
      : ` The points of frame ${state.markedFrame} are tracked to each; a frame where the track is lost is left out, with the reason.`)
      : "";
    return this.measured(selection, info) + tracked;
  }

  private measured(selection: FrameSelection, info: VideoInfo): string {
    if (selection.sharpest !== undefined) {
      return `Measures the ${selection.sharpest} sharpest of ${candidates(selection, info).length} frames.`;
    }
    const frames = selection.indices ?? candidates(selection, info);
    const shown = frames.slice(0, 12).join(", ") + (frames.length > 12 ? ", …" : "");
    return `Measures ${frames.length} frame${frames.length === 1 ? "" : "s"}: ${shown}.`;
  }

  /** The spec's `frames`; throws an Error saying what to fix. `marked`: the frame marked on. */
  read(info: VideoInfo, marked: number | null): FrameSelection {
    const kind = value("select-kind");
    if (kind === "indices") return { indices: indices(value("select-indices"), info.frame_count) };
    const selection: FrameSelection = {};
    const start = seconds("select-start", "From");
    const end = seconds("select-end", "To");
    if (start !== undefined) selection.start_s = start;
    if (end !== undefined) selection.end_s = end;
    if (start !== undefined && end !== undefined && end <= start) {
      throw new Error(`“To” (${end} s) must be after “From” (${start} s).`);
    }
    if ((start !== undefined || end !== undefined) && !info.fps) {
      throw new Error("This video states no frame rate: choose the frames by number instead.");
    }
    if (kind === "sharpest") selection.sharpest = whole("select-sharpest", "How many sharpest frames");
    if (kind !== "every") return selection;
    selection.every = whole("select-every", "N (every Nth frame)");
    const chosen = candidates(selection, info);
    // The marked frame is measured too: when every Nth misses it, the frames are listed instead.
    if (marked === null || chosen.includes(marked)) return selection;
    return { indices: [...chosen, marked].sort((a, b) => a - b) };
  }
}

/** The frames in [start_s, end_s), every Nth from the first (prismcore.video.frame_select._candidates). */
export function candidates(selection: FrameSelection, info: VideoInfo): number[] {
  const n = info.frame_count;
  let [first, stop] = [0, n];
  if (selection.start_s !== undefined) first = Math.ceil(selection.start_s * info.fps - 1e-6);
  if (selection.end_s !== undefined) stop = Math.min(n, Math.ceil(selection.end_s * info.fps - 1e-6));
  const out: number[] = [];
  for (let i = first; i < stop; i += selection.every ?? 1) out.push(i);
  if (!out.length) throw new Error(`That picks no frame of the video (${info.duration_s.toFixed(2)} s, ${n} frames).`);
  return out;
}

function indices(text: string, count: number): number[] {
  const parts = text.split(/[\s,]+/).filter(Boolean);
  if (!parts.length) throw new Error("Give the frame numbers to measure, e.g. 0, 12, 30.");
  const out: number[] = [];
  for (const part of parts) {
    const n = Number(part);
    if (!Number.isInteger(n) || n < 0) throw new Error(`“${part}” is not a frame number.`);
    if (n >= count) throw new Error(`There is no frame ${n}: the video has frames 0 to ${count - 1}.`);
    if (out.includes(n)) throw new Error(`Frame ${n} is listed twice.`);
    out.push(n);
  }
  return out.sort((a, b) => a - b);
}

function seconds(id: string, what: string): number | undefined {
  const text = value(id);
  if (text === "") return undefined;
  const v = Number(text);
  if (!Number.isFinite(v) || v < 0) throw new Error(`“${what}” must be 0 seconds or more (got “${text}”).`);
  return v;
}

function whole(id: string, what: string): number {
  const text = value(id);
  const v = Number(text);
  if (text === "" || !Number.isInteger(v) || v < 1) throw new Error(`${what} must be a whole number from 1 (got “${text}”).`);
  return v;
}
