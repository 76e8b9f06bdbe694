// A video whose seven points were marked on one frame and tracked to the others (points_frame):
// the track on a scrubber. The slider walks the selected frames; each tracked frame is drawn as
// the worker decodes it (the upload's frame, fetched through the API as for marking) with its
// tracked points and faces over it; a frame the tracking left out is marked on the strip under
// the slider, and its reason is shown when it is picked and listed below.

import { getJson, message } from "./api";
import type { Item, Job, Point } from "./types";
import { videoFrame } from "./video";

interface TrackEntry {
  points?: Point[];
  quality?: { confidence: number; inliers: number; fb_error_px: number } | null;
  reason?: string | null;
}
/** tracked_points.json: per frame index its seven points (P1..P7) and their quality, or why it is left out. */
export type Track = Record<string, TrackEntry>;

const WIDTH = 640; // the canvas's width at most, px
const FRONT_COLOUR = "rgb(0, 200, 255)";
const SIDE_COLOUR = "rgb(255, 140, 0)";
export const POINT_COLOUR = "rgb(255, 212, 0)";

const el = <K extends keyof HTMLElementTagNameMap>(tag: K, text = "", attrs: Record<string, string> = {}) => {
  const node = document.createElement(tag);
  node.textContent = text;
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  return node;
};

/** Was the item's video tracked from one marked frame (and is its track stored)? */
export function isTracked(item: Item): boolean {
  return Boolean(item.downloads.tracked_points);
}

/** The track view of `item`; it fills itself in once tracked_points.json has come. */
export function trackView(job: Job, item: Item): HTMLElement {
  const section = el("section", "", { id: "track-view", "aria-labelledby": "h-track" });
  const tracking = (item.result?.summary as { tracking?: { points_frame: number } } | null | undefined)?.tracking;
  section.append(el("h3", tracking ? `Points tracked from frame ${tracking.points_frame}` : "Points tracked",
    { id: "h-track" }));
  const status = el("p", "Loading the track…", { id: "track-status", role: "status" });
  section.append(status);
  void getJson<Track>(`/v1/jobs/${job.id}/items/${item.index}/tracked_points.json`)
    .then((track) => fill(section, status, track, uploadOf(item)))
    .catch((err) => { status.textContent = `The track could not be loaded: ${message(err)}`; });
  return section;
}

/** The upload the video came from (its frames are shown as the worker decodes them), if one. */
function uploadOf(item: Item): string | null {
  const video = (item.result?.summary as { video?: { reference?: string } } | null | undefined)?.video;
  const match = /^upload:(\w+)$/.exec(video?.reference ?? "");
  return match ? match[1] : null;
}

function fill(section: HTMLElement, status: HTMLElement, track: Track, upload: string | null): void {
  const frames = Object.keys(track).map(Number).sort((a, b) => a - b);
  if (!frames.length) {
    status.textContent = "No frame was tracked.";
    return;
  }
  const row = el("div", "", { class: "track-row" });
  const label = el("label", "Tracked frame", { for: "track-slider" });
  const slider = el("input", "", { id: "track-slider", type: "range", min: "0", max: String(frames.length - 1),
    step: "1", value: "0" }) as HTMLInputElement;
  row.append(label, slider);
  // The strip: one button per frame, the frames left out marked (and their reason as a tooltip).
  const strip = el("ol", "", { id: "track-strip", "aria-label": "Frames of the track" });
  const buttons = frames.map((f, k) => {
    const entry = track[String(f)];
    const left = !entry.points;
    const button = el("button", String(f), {
      type: "button", "data-frame": String(f), class: left ? "left-out" : "tracked",
      "aria-label": left ? `Frame ${f}: left out (${entry.reason ?? "no reason given"})` : `Frame ${f}: tracked`,
    });
    if (left) button.title = entry.reason ?? "";
    button.addEventListener("click", () => { slider.value = String(k); void show(k); });
    const li = el("li");
    li.append(button);
    strip.append(li);
    return button;
  });
  const canvas = el("canvas", "", { id: "track-canvas", "aria-label": "The frame with its tracked points" }) as HTMLCanvasElement;
  const leftOut = frames.filter((f) => !track[String(f)].points);
  const list = el("ul", "", { id: "track-left-out" });
  for (const f of leftOut) list.append(el("li", `Frame ${f}: ${track[String(f)].reason ?? "no reason given"}`));
  const listHead = el("p", leftOut.length ? `Frames left out (${leftOut.length}):` : "No frame was left out.",
    { id: "track-left-out-head" });
  section.append(row, strip, canvas, listHead, list);

  let loading = 0;
  const show = async (k: number) => {
    const f = frames[k];
    const entry = track[String(f)];
    const load = ++loading;
    buttons.forEach((b, i) => b.setAttribute("aria-current", String(i === k)));
    canvas.dataset.frame = String(f);
    const words = entry.points
      ? `Frame ${f}: tracked` + (entry.quality ? ` (confidence ${entry.quality.confidence.toFixed(2)})` : "") + "."
      : `Frame ${f} was left out: ${entry.reason ?? "no reason given"}.`;
    let image: ImageBitmap | null = null;
    if (upload) {
      try {
        image = await videoFrame(upload, f);
      } catch (err) {
        if (load === loading) status.textContent = `${words} The frame could not be shown: ${message(err)}`;
      }
    }
    if (load !== loading) return;
    draw(canvas, image, entry.points ?? null);
    canvas.dataset.shown = String(f); // drawn: what a reader (or a test) waits on
    status.textContent = words + (upload ? "" : " (The video is not an upload: its frames are not shown.)");
  };
  slider.addEventListener("input", () => void show(Number(slider.value)));
  void show(0);
}

/** The frame (or a dark field of the points' extent) and the seven points with both faces. */
function draw(canvas: HTMLCanvasElement, image: ImageBitmap | null, points: Point[] | null): void {
  const w = image?.width ?? Math.max(WIDTH, ...(points ?? []).map((p) => p[0] + 20));
  const h = image?.height ?? Math.max(WIDTH * 0.6, ...(points ?? []).map((p) => p[1] + 20));
  const s = Math.min(1, WIDTH / w);
  canvas.width = Math.round(w * s);
  canvas.height = Math.round(h * s);
  canvas.dataset.scale = String(s);
  const ctx = canvas.getContext("2d")!;
  ctx.fillStyle = "#30343a";
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  if (image) ctx.drawImage(image, 0, 0, canvas.width, canvas.height);
  if (!points) return;
  const at = (i: number): Point => [points[i][0] * s, points[i][1] * s];
  const [p1, p2, p3, p4, p5, p6, p7] = points.map((_, i) => i);
  // The second face: P4 is the front corner it shares (P2: a right side; P1: left or top), P7
  // its far corner beside the other shared front corner.
  const d = (a: number, b: number) => Math.hypot(points[a][0] - points[b][0], points[a][1] - points[b][1]);
  const side = d(p4, p2) < d(p4, p1) ? [p2, p5, p7, p3] : d(p7, p6) < d(p7, p2) ? [p1, p5, p7, p6] : [p1, p5, p7, p2];
  polygon(ctx, [p1, p2, p3, p6].map(at), FRONT_COLOUR);
  polygon(ctx, side.map(at), SIDE_COLOUR);
  ctx.font = "12px sans-serif";
  points.forEach((_, i) => {
    const [x, y] = at(i);
    ctx.fillStyle = POINT_COLOUR;
    ctx.beginPath();
    ctx.arc(x, y, 4, 0, 2 * Math.PI);
    ctx.fill();
    if (i === 3) return; // P4 sits on P2 or P1: one label
    ctx.fillStyle = "rgba(0, 0, 0, 0.7)";
    ctx.fillRect(x + 6, y - 16, 20, 14);
    ctx.fillStyle = "#fff";
    ctx.fillText(`P${i + 1}`, x + 8, y - 5);
  });
}

function polygon(ctx: CanvasRenderingContext2D, quad: Point[], colour: string): void {
  ctx.strokeStyle = colour;
  ctx.lineWidth = 2;
  ctx.beginPath();
  quad.forEach(([x, y], i) => (i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
  ctx.closePath();
  ctx.stroke();
}
