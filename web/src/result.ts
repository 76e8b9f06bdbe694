// The result panel: per scan the dimensions with their uncertainty, where the focal length came
// from, point count and point loss, download links, the overlay picture of the fit, and the cloud
// in the 3D view (preview and overlay fetched through the API on this origin, never from S3). A
// video shows its summary and frames (video-result.ts), and the cloud of the frame chosen.
// Several photos of one part measured as one box (joint-result.ts) make no cloud: no 3D view.

import { call, message } from "./api";
import type { ColourMode } from "./colours";
import { LINKS } from "./formats";
import { jointFocal, jointLine, jointOf, jointTable } from "./joint-result";
import { pixelsNote } from "./pixels";
import { ResultsTableView } from "./results-table";
import { isTracked, trackView } from "./track-view";
import type { Dimension, Frame, Item, Job, Result } from "./types";
import { badge, deviationText } from "./verdicts";
import { isVideoItem, videoResult } from "./video-result";
import { type BoxAnnotation, Viewer } from "./viewer";
import { DIMENSIONS as DIMS, flag, warningList } from "./warnings";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
// The overlay's picture format, named by its file's suffix: a JPEG (overlay.jpg) since the
// worker stores one, a PNG (overlay.png) for a job stored before.
const PICTURES: Record<string, string> = { jpg: "JPEG", jpeg: "JPEG", png: "PNG", webp: "WebP" };

/** A download's label: the overlay's names the format its link's file is in. */
function linkText(kind: string, text: string, url: string): string {
  if (kind !== "overlay") return text;
  const name = new URL(url, location.href).pathname;
  const suffix = name.slice(name.lastIndexOf(".") + 1).toLowerCase();
  const format = PICTURES[suffix] ?? (suffix && !suffix.includes("/") ? suffix.toUpperCase() : "");
  return format ? `${text} (${format})` : text;
}
const SOURCES: Record<string, string> = {
  given: "given", camera: "calibrated camera", exif: "from the photo's EXIF", pooled: "pooled over the photos",
  fitted: "fitted to the box", none: "not used (square-on model)",
};

export class ResultPanel {
  private viewer: Viewer | null = null;
  private job: Job | null = null;
  private loading = 0; // the latest load; an older one that finishes late is dropped
  private table = new ResultsTableView();
  private model = false; // the 3D view shows the glb box model rather than the cloud

  constructor() {
    $("result-item").addEventListener("change", () => void this.showItem());
    $("result-frame").addEventListener("change", () => void this.showCloud());
    this.table.onOpen = (item, frame) => void this.select(item, frame);
    $("show-cloud").addEventListener("click", () => this.showModel(false));
    $("show-model").addEventListener("click", () => this.showModel(true));
    $("show-dims").addEventListener("change", (e) => this.viewer?.annotations((e.target as HTMLInputElement).checked));
    $("color-mode").addEventListener("change", () => this.viewer?.colour(this.mode()));
    $("point-size").addEventListener("input", (e) =>
      this.viewer?.pointSize(Number((e.target as HTMLInputElement).value)));
    $("reset-view").addEventListener("click", () => this.viewer?.reset());
    // The fit on the photo: a thumbnail beside the dimensions, the whole width when asked.
    $("overlay-zoom").addEventListener("click", () =>
      this.overlayLarge(!$("overlay-figure").classList.contains("large")));
  }

  /** The fit on the photo at the column's width (`large`), or a thumbnail beside the dimensions. */
  overlayLarge(large: boolean): void {
    $("overlay-figure").classList.toggle("large", large);
    $("overlay-zoom").setAttribute("aria-expanded", String(large));
    $("overlay-zoom").setAttribute("aria-label", `The fit on the photo: show it ${large ? "smaller" : "larger"}`);
  }

  private mode(): ColourMode {
    return $<HTMLSelectElement>("color-mode").value as ColourMode;
  }

  /** Show `job`'s result; `table`: its table even for one scan (a station's job). */
  show(job: Job, table = false): void {
    this.job = job;
    $("result").hidden = false;
    const select = $<HTMLSelectElement>("result-item");
    const first = job.items.find((i) => i.state === "succeeded") ?? job.items[0];
    select.replaceChildren(...job.items.map((i) =>
      new Option(`Scan ${i.index + 1}: ${i.state}${i.result?.quality ? `, ${i.result.quality.verdict}` : ""}`,
        String(i.index), false, i === first)));
    void this.table.load(job, table);
    void this.showItem();
  }

  /** Open one scan (and for a video one frame) of the job: the table's click-through. */
  async select(item: number, frame: number | null): Promise<void> {
    $<HTMLSelectElement>("result-item").value = String(item);
    await this.showItem(frame);
    $("h-result").focus();
    $("result").scrollIntoView({ block: "start" });
  }

  private showModel(model: boolean): void {
    this.model = model;
    $("show-cloud").setAttribute("aria-pressed", String(!model));
    $("show-model").setAttribute("aria-pressed", String(model));
    void this.showCloud();
  }

  private item(): Item {
    return this.job!.items[Number($<HTMLSelectElement>("result-item").value)];
  }

  private async showItem(frameWanted: number | null = null): Promise<void> {
    const item = this.item();
    const video = isVideoItem(item);
    const shown = video ? { top: videoResult(item), warnings: [], details: [] } : summary(item);
    if (isTracked(item)) shown.top.push(trackView(this.job!, item));
    $("result-body").replaceChildren(...shown.top);
    $("result-warnings").replaceChildren(...shown.warnings);
    $("result-details").replaceChildren(...shown.details);
    const measured = video ? item.frames.filter((f) => f.state === "succeeded") : [];
    $("result-frame-row").hidden = !measured.length;
    const chosen = measured.find((f) => f.index === frameWanted) ?? measured[0];
    $<HTMLSelectElement>("result-frame").replaceChildren(...measured.map((f) =>
      new Option(`Frame ${f.index}`, String(f.index), false, f === chosen)));
    this.table.mark(item.index, video ? (chosen?.index ?? null) : null);
    $("viewer-box").hidden = jointOf(item) !== null; // no cloud to show
    const glb = !video && Boolean(item.downloads.glb);
    $("show-model").hidden = !glb;
    if (!glb && this.model) this.showModel(false);
    else await this.showCloud();
  }

  /** The item's cloud, or for a video the cloud of the frame chosen, in the 3D view. */
  private async showCloud(): Promise<void> {
    const job = this.job!;
    const item = this.item();
    const frame = frameChosen(item);
    const status = $("viewer-status");
    const load = ++this.loading;
    this.viewer?.clear();
    if (jointOf(item)) {
      $("overlay-figure").hidden = true; // nor a fit drawn on one photo
      status.textContent = "";
      return;
    }
    if (frame === undefined || (frame === null && item.state !== "succeeded")) {
      $("overlay-figure").hidden = true; // never the fit of the scan shown before
      status.textContent = "No cloud for this scan.";
      return;
    }
    const result = frame ? frame.result : item.result;
    status.textContent = "Loading the 3D view…";
    const path = `/v1/jobs/${job.id}/items/${item.index}` + (frame ? `/frames/${frame.index}` : "");
    void this.showOverlay(path, load);
    try {
      if (this.model && !frame) return await this.showGlb(path, load);
      const response = await call(`${path}/preview.ply`);
      const data = await response.arrayBuffer();
      if (load !== this.loading) return;
      this.viewer ??= new Viewer($("viewer"));
      this.viewer.pointSize(Number($<HTMLInputElement>("point-size").value));
      const { shown, total } = this.viewer.show(data, this.mode(), annotation(result));
      this.viewer.annotations($<HTMLInputElement>("show-dims").checked);
      const of = result && result.points > shown ? ` of ${result.points.toLocaleString("en")}` : "";
      const which = frame ? ` of frame ${frame.index}` : "";
      status.textContent = `Showing ${shown.toLocaleString("en")}${of} points${which}` +
        (total > shown ? ` (thinned from ${total.toLocaleString("en")} for display).` : ".");
      $("viewer").dataset.points = String(shown);
    } catch (err) {
      if (load === this.loading) status.textContent = `The 3D view could not be shown: ${message(err)}`;
    }
  }

  /** The fitted box as the worker's textured glTF model (box.glb, relayed through the API). */
  private async showGlb(path: string, load: number): Promise<void> {
    const data = await (await call(`${path}/box.glb`)).arrayBuffer();
    if (load !== this.loading) return;
    this.viewer ??= new Viewer($("viewer"));
    await this.viewer.showModel(data, annotation(this.item().result));
    this.viewer.annotations($<HTMLInputElement>("show-dims").checked);
    $("viewer-status").textContent = "Showing the box model (glTF): the fitted box, its faces textured from the photo.";
    $("viewer").dataset.points = "0";
  }

  /** The fit drawn on the photo (overlay.jpg; a PNG for a job from before), beside the dimensions. */
  private async showOverlay(path: string, load: number): Promise<void> {
    const figure = $("overlay-figure");
    const img = $<HTMLImageElement>("overlay");
    figure.hidden = true;
    if (img.src.startsWith("blob:")) URL.revokeObjectURL(img.src);
    img.removeAttribute("src");
    try {
      const blob = await (await call(`${path}/overlay.jpg`)).blob();
      if (load !== this.loading) return;
      img.src = URL.createObjectURL(blob);
      figure.hidden = false;
    } catch {
      // No overlay (a scan from before overlays, or one that failed): the figure stays hidden.
    }
  }
}

/** "120.00 ± 0.15 mm", or without ± when the uncertainty is unknown. */
/** A dimension as shown: "79.99 ± 0.59 mm", or "120.00 mm (given)" for the known edge's. */
function shownAs(r: Result, dim: Dimension): string {
  if (r.given_dimension === dim) return `${r.dimensions[dim].toFixed(2)} ${r.dimensions.unit} (given)`;
  return withSigma(r.dimensions[dim], r.uncertainty?.[dim], r.dimensions.unit);
}

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

interface Summary {
  top: HTMLElement[]; // the part's verdict and the dimensions, beside the overlay thumbnail
  warnings: HTMLElement[]; // right under them
  details: HTMLElement[]; // after the 3D view: points, focal length, fit; downloads
}

function summary(item: Item): Summary {
  if (item.state !== "succeeded" || !item.result) {
    const p = document.createElement("p");
    p.className = item.state === "failed" ? "error" : "";
    p.textContent = item.error ? `This scan failed: ${item.error}` : `This scan is ${item.state}.`;
    return { top: [p], warnings: [], details: [] };
  }
  const r = item.result;
  const unit = r.dimensions.unit;
  const quality = r.quality ?? null;
  const out: HTMLElement[] = [];
  const warned = warningList(r.warnings, true);
  const joint = r.joint ?? null;
  if (quality) {
    const p = document.createElement("p");
    p.className = "part-verdict";
    p.id = "part-verdict";
    const n = Object.keys(quality.dimensions).length;
    p.append("Part: ", badge(quality.verdict, "strong"),
      ` (${quality.counts.pass} of ${n} dimensions within tolerance at ±${quality.k} σ)`);
    out.push(p);
  }
  if (joint) out.push(jointLine(joint));
  if (unit === "px") out.push(pixelsNote());
  const dl = document.createElement("dl");
  dl.id = "dimensions";
  const details = document.createElement("dl");
  details.id = "details";
  const add = (key: string, value: string, cls = "wide", into = details): HTMLElement => {
    const dt = document.createElement("dt");
    const dd = document.createElement("dd");
    dt.textContent = key;
    dd.textContent = value;
    dd.className = cls;
    dd.dataset.field = key.toLowerCase().replaceAll(" ", "-");
    into.append(dt, dd);
    return dd;
  };
  for (const dim of DIMS) {
    const name = dim.charAt(0).toUpperCase() + dim.slice(1);
    const dd = add(name, shownAs(r, dim), "dim", dl);
    (dd.previousElementSibling as HTMLElement).className = "big";
    // The known edge's length was given, not measured: plain, never bold as a result.
    if (r.given_dimension === dim) dd.classList.add("given");
    // A figure a warning qualifies is drawn plain, flagged, and described by the warning.
    const refs = warned.of[dim];
    if (refs.length) {
      dd.classList.add("warned");
      dd.dataset.warned = "true";
      dd.setAttribute("aria-describedby", refs.map((w) => w.id).join(" "));
    }
    dl.append(flag(refs));
    const judged = quality?.dimensions[dim];
    const verdict = document.createElement("dd");
    verdict.className = "deviation";
    verdict.dataset.verdictOf = dim;
    if (judged) verdict.append(badge(judged.verdict), " ", deviationText(judged));
    dl.append(verdict);
  }
  if (joint) {
    const focal = jointFocal(r, joint);
    if (focal) add("Focal length", focal);
  } else {
    add("Points", r.points.toLocaleString("en"));
    add("Point loss", `${(r.point_loss * 100).toFixed(2)} %`);
  }
  if (r.focal_source && !joint) {
    const f = r.focal_px ? `${Math.round(r.focal_px)} px, ` : "";
    add("Focal length", `${f}${SOURCES[r.focal_source] ?? r.focal_source}`);
  }
  if (r.fit_rms_px !== undefined && r.fit_rms_px !== null) add("Fit", `${r.fit_rms_px.toFixed(2)} px RMS`);
  if (r.side_face) add("Second face", r.side_face);
  if (r.points_source === "station") add("Measured", "on the station: found against its support, no points, no scale");
  if (r.points_source === "auto") {
    const c = r.points_confidence;
    add("Reference points", `found automatically${c !== undefined && c !== null ? ` (confidence ${c.toFixed(2)})` : ""}`);
  }
  out.push(dl);
  const links = document.createElement("p");
  links.className = "downloads";
  for (const [kind, text] of LINKS) {
    if (!item.downloads[kind]) continue;
    const a = document.createElement("a");
    a.href = item.downloads[kind];
    a.textContent = `Download ${linkText(kind, text, item.downloads[kind])}`;
    a.rel = "noopener";
    links.append(a);
  }
  const more = joint ? [jointTable(joint, unit)] : [];
  return { top: out, warnings: warned.list ? [warned.list] : [], details: [details, ...more, links] };
}

/** The fitted box and its dimension labels for the 3D view, from a scan's result. */
function annotation(r: Result | null): BoxAnnotation | undefined {
  if (!r) return undefined;
  const unit = r.dimensions.unit;
  const warned = warningList(r.warnings, true).of;
  const labels = Object.fromEntries(DIMS.map((d) => {
    const name = d.charAt(0).toUpperCase() + d.slice(1);
    const verdict = r.quality?.dimensions[d]?.verdict;
    const flagged = warned[d].length > 0; // a warning qualifies it: "⚠" on the label too
    return [d, { text: `${name} ${shownAs(r, d)}${flagged ? " ⚠" : ""}`, verdict,
      warned: flagged }];
  })) as BoxAnnotation["labels"];
  return { size: [r.dimensions.width, r.dimensions.height, r.dimensions.depth], unit, labels };
}
