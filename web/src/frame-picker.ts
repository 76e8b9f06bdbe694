// Step 2 for a video: the frame the points are marked on, picked with a slider or by number and
// fetched from the service (video.ts); with per-frame points each frame keeps its own.

import { message } from "./api";
import { sequence } from "./points";
import * as S from "./state";
import { videoFrame } from "./video";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
const SLIDE_MS = 120; // a slider being dragged asks for the frame it rests on, not every one passed

export class FramePicker {
  onShown: () => void = () => {};
  private loading = 0; // the latest request; an older one that finishes late is dropped
  private timer = 0;

  constructor() {
    const slider = $<HTMLInputElement>("frame-slider");
    const number = $<HTMLInputElement>("frame-number");
    slider.addEventListener("input", () => {
      number.value = slider.value;
      window.clearTimeout(this.timer);
      this.timer = window.setTimeout(() => void this.go(Number(slider.value)), SLIDE_MS);
    });
    number.addEventListener("change", () => {
      const info = S.photoShown("front")?.video?.info;
      if (!info || !Number.isInteger(number.valueAsNumber)) return;
      const n = Math.min(info.frame_count - 1, Math.max(0, number.valueAsNumber));
      number.value = slider.value = String(n);
      void this.go(n);
    });
  }

  /** Show frame `n` of the front video once the service has it. */
  async go(n: number): Promise<void> {
    const entry = S.photoShown("front");
    if (!entry?.video?.info || !entry.upload || n === entry.video.frame) return;
    const load = ++this.loading;
    $("frame-status").textContent = `Loading frame ${n}…`;
    try {
      const bitmap = await videoFrame(entry.upload.id, n);
      if (load !== this.loading || S.photoShown("front") !== entry) return;
      if (S.state.perFrame) S.switchFrame(entry.video.frame, n);
      entry.bitmap = bitmap;
      entry.video.frame = n;
      this.render();
      this.onShown();
    } catch (err) {
      if (load === this.loading) $("frame-status").textContent = `Frame ${n} could not be shown: ${message(err)}`;
    }
  }

  render(): void {
    const entry = S.photoShown("front");
    const video = entry?.video;
    $("frame-picker").hidden = !video?.info;
    if (!video?.info) return;
    const { info, frame } = video;
    for (const id of ["frame-slider", "frame-number"]) {
      const input = $<HTMLInputElement>(id);
      input.max = String(info.frame_count - 1);
      if (document.activeElement !== input || id === "frame-number") input.value = String(frame);
    }
    $("video-info").textContent = `${entry!.name}: ${info.frame_count} frames` +
      (info.fps ? ` at ${info.fps.toLocaleString("en", { maximumFractionDigits: 3 })} fps` : "") +
      `, ${info.width} × ${info.height}, codec ${info.codec}.`;
    const time = info.fps ? ` (${(frame / info.fps).toFixed(3)} s)` : "";
    $("frame-status").textContent = `Showing frame ${frame} of ${info.frame_count}${time}.`;
    $("marked-frames").textContent = this.marked();
  }

  private marked(): string {
    if (!S.state.perFrame) {
      const at = S.state.markedFrame;
      if (at === null) return "";
      return S.state.tracked ? `The points were marked on frame ${at}; the service tracks them to the other frames measured.`
        : `The points were marked on frame ${at}; they apply to every frame measured.`;
    }
    const all = S.allFrameMarks();
    const frames = Object.keys(all).map(Number).sort((a, b) => a - b);
    if (!frames.length) return "No frame marked yet: each frame you mark is measured with its own points.";
    const needed = sequence(S.state.extra).length;
    return "Marked frames: " + frames.map((f) => {
      const placed = Object.keys(all[f]).length;
      return placed >= needed ? `${f}` : `${f} (${placed} of ${needed} points)`;
    }).join(", ") + ".";
  }
}
