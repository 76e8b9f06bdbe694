// The result panel: per scan the dimensions with their uncertainty, where the focal length came
// from, point count and point loss, download links, the overlay picture of the fit, and the cloud
// in the 3D view (preview and overlay fetched through the API on this origin, never from S3). A
// video shows its summary and frames (video-result.ts), and the cloud of the frame chosen.

import { call, message } from "./api";
import type { ColourMode } from "./colours";
import type { Frame, Item, Job } from "./types";
import { isVideoItem, videoResult } from "./video-result";
import { Viewer } from "./viewer";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
const LINKS: [string, string][] = [["csv", "Cloud (CSV)"], ["ply", "Cloud (PLY)"], ["report", "Report (JSON)"],
  ["overlay", "Fit overlay (PNG)"]];
const SOURCES: Record<string, string> = {
  given: "given", camera: "calibrated camera", exif: "from the photo's EXIF", pooled: "pooled over the photos",
  fitted: "fitted to the box", none: "not used (square-on model)",
};

export class ResultPanel {
  private viewer: Viewer | null = null;
  private job: Job | null = null;
  private loading = 0; // the latest load; an older one that finishes late is dropped

  constructor() {
    $("result-item").addEventListener("change", () => void this.showItem());
    $("result-frame").addEventListener("change", () => void this.showCloud());
    $("color-mode").addEventListener("change", () => this.viewer?.colour(this.mode()));
    $("point-size").addEventListener("input", (e) =>
      this.viewer?.pointSize(Number((e.target as HTMLInputElement).value)));
    $("reset-view").addEventListener("click", () => this.viewer?.reset());
  }

  private mode(): ColourMode {
    return $<HTMLSelectElement>("color-mode").value as ColourMode;
  }

  show(job: Job): void {
    this.job = job;
    $("result").hidden = false;
    const select = $<HTMLSelectElement>("result-item");
    const first = job.items.find((i) => i.state === "succeeded") ?? job.items[0];
    select.replaceChildren(...job.items.map((i) =>
      new Option(`Scan ${i.index + 1}: ${i.state}`, String(i.index), false, i === first)));
    void this.showItem();
  }

  private item(): Item {
    return this.job!.items[Number($<HTMLSelectElement>("result-item").value)];
  }

  private async showItem(): Promise<void> {
    const item = this.item();
    const video = isVideoItem(item);
    $("result-body").replaceChildren(...(video ? videoResult(item) : summary(item)));
    const measured = video ? item.frames.filter((f) => f.state === "succeeded") : [];
    $("result-frame-row").hidden = !measured.length;
    $<HTMLSelectElement>("result-frame").replaceChildren(...measured.map((f, i) =>
      new Option(`Frame ${f.index}`, String(f.index), false, i === 0)));
    await this.showCloud();
  }

  /** The item's cloud, or for a video the cloud of the frame chosen, in the 3D view. */
  private async showCloud(): Promise<void> {
    const job = this.job!;
    const item = this.item();
    const frame = frameChosen(item);
    const status = $("viewer-status");
    const load = ++this.loading;
    this.viewer?.clear();
    if (frame === undefined || (frame === null && item.state !== "succeeded")) {
      status.textContent = "No cloud for this scan.";
      return;
    }
    const result = frame ? frame.result : item.result;
    status.textContent = "Loading the 3D view…";
    const path = `/v1/jobs/${job.id}/items/${item.index}` + (frame ? `/frames/${frame.index}` : "");
    void this.showOverlay(path, load);
    try {
      const response = await call(`${path}/preview.ply`);
      const data = await response.arrayBuffer();
      if (load !== this.loading) return;
      this.viewer ??= new Viewer($("viewer"));
      this.viewer.pointSize(Number($<HTMLInputElement>("point-size").value));
      const { shown, total } = this.viewer.show(data, this.mode());
      const of = result && result.points > shown ? ` of ${result.points.toLocaleString("en")}` : "";
      const which = frame ? ` of frame ${frame.index}` : "";
      status.textContent = `Showing ${shown.toLocaleString("en")}${of} points${which}` +
        (total > shown ? ` (thinned from ${total.toLocaleString("en")} for display).` : ".");
      $("viewer").dataset.points = String(shown);
    } catch (err) {
      if (load === this.loading) status.textContent = `The 3D view could not be shown: ${message(err)}`;
    }
  }

  /** The fit drawn on the photo (overlay.png), under the dimensions. */
  private async showOverlay(path: string, load: number): Promise<void> {
    const figure = $("overlay-figure");
    const img = $<HTMLImageElement>("overlay");
    figure.hidden = true;
    if (img.src.startsWith("blob:")) URL.revokeObjectURL(img.src);
    img.removeAttribute("src");
    try {
      const blob = await (await call(`${path}/overlay.png`)).blob();
      if (load !== this.loading) return;
      img.src = URL.createObjectURL(blob);
      figure.hidden = false;
    } catch {
      // No overlay (a scan from before overlays, or one that failed): the figure stays hidden.
    }
  }
}

/** "120.00 ± 0.15 mm", or without ± when the uncertainty is unknown. */
export function withSigma(value: number, sigma: number | undefined, unit: string): string {
  return sigma === undefined || !Number.isFinite(sigma)
    ? `${value.toFixed(2)} ${unit}` : `${value.toFixed(2)} ± ${sigma.toFixed(2)} ${unit}`;
}

/** The video frame whose cloud to show: null for a photo, undefined when no frame was measured. */
function frameChosen(item: Item): Frame | null | undefined {
  if (!isVideoItem(item)) return null;
  const chosen = $<HTMLSelectElement>("result-frame").value;
  return item.frames.find((f) => String(f.index) === chosen);
}

function summary(item: Item): HTMLElement[] {
  if (item.state !== "succeeded" || !item.result) {
    const p = document.createElement("p");
    p.className = item.state === "failed" ? "error" : "";
    p.textContent = item.error ? `This scan failed: ${item.error}` : `This scan is ${item.state}.`;
    return [p];
  }
  const r = item.result;
  const unit = r.dimensions.unit;
  const sigma = r.uncertainty ?? undefined;
  const rows: [string, string][] = [
    ["Width", withSigma(r.dimensions.width, sigma?.width, unit)],
    ["Height", withSigma(r.dimensions.height, sigma?.height, unit)],
    ["Depth", withSigma(r.dimensions.depth, sigma?.depth, unit)],
    ["Points", r.points.toLocaleString("en")],
    ["Point loss", `${(r.point_loss * 100).toFixed(2)} %`],
  ];
  if (r.focal_source) {
    const f = r.focal_px ? `${Math.round(r.focal_px)} px, ` : "";
    rows.push(["Focal length", `${f}${SOURCES[r.focal_source] ?? r.focal_source}`]);
  }
  if (r.fit_rms_px !== undefined && r.fit_rms_px !== null) rows.push(["Fit", `${r.fit_rms_px.toFixed(2)} px RMS`]);
  if (r.side_face) rows.push(["Second face", r.side_face]);
  const dl = document.createElement("dl");
  dl.id = "dimensions";
  for (const [k, v] of rows) {
    const dt = document.createElement("dt");
    const dd = document.createElement("dd");
    dt.textContent = k;
    dd.textContent = v;
    dd.dataset.field = k.toLowerCase().replaceAll(" ", "-");
    dl.append(dt, dd);
  }
  const links = document.createElement("p");
  links.className = "downloads";
  for (const [kind, text] of LINKS) {
    if (!item.downloads[kind]) continue;
    const a = document.createElement("a");
    a.href = item.downloads[kind];
    a.textContent = `Download ${text}`;
    a.rel = "noopener";
    links.append(a);
  }
  const out: HTMLElement[] = [dl, links];
  if (r.warnings.length) {
    const ul = document.createElement("ul");
    ul.setAttribute("aria-label", "Warnings");
    ul.className = "warnings";
    ul.replaceChildren(...r.warnings.map((w) => Object.assign(document.createElement("li"), { textContent: w })));
    out.push(ul);
  }
  return out;
}
