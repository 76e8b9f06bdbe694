// A video item's result: the summary over its frames (median and spread of each dimension, a
// small table) and the list of frames, each with its state, dimensions or error, and downloads.

import type { Dimension, Frame, Item, Summary } from "./types";
import { FRAME_LINKS } from "./formats";
import { pixelsNote } from "./pixels";
import { warningList } from "./warnings";

const DIMENSIONS: Dimension[] = ["width", "height", "depth"];
// A frame has the formats its item asked for (the service's default: CSV and PLY unless the operator chose others,
// LAZ, glb, STEP and the drawing only with a scale) and its report: FRAME_LINKS (the format table's) links them.

const el = <K extends keyof HTMLElementTagNameMap>(tag: K, text = "", attrs: Record<string, string> = {}) => {
  const node = document.createElement(tag);
  node.textContent = text;
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  return node;
};

const capital = (s: string) => s.charAt(0).toUpperCase() + s.slice(1);

export function isVideoItem(item: Item): boolean {
  // A tracked video measured as one box has a summary of its tracking only: it is a joint result.
  return item.frames.length > 0 || Boolean(item.result?.summary?.frames);
}

export function videoResult(item: Item): HTMLElement[] {
  const out: HTMLElement[] = [];
  const summary = item.result?.summary;
  if (item.state === "failed") out.push(el("p", `This video failed: ${item.error ?? "no reason given"}`, { class: "error" }));
  if (summary) {
    const { selected, measured, failed } = summary.frames;
    out.push(el("p", `Measured ${measured} of ${selected} frames` + (failed ? `; ${failed} could not be measured.` : ".")));
    if (summary.unit === "px") out.push(pixelsNote());
    out.push(summaryTable(summary.dimensions, summary.unit ?? ""));
    if (item.downloads.summary) {
      const links = el("p", "", { class: "downloads" });
      links.append(Object.assign(el("a", "Download the summary (JSON)"), { href: item.downloads.summary, rel: "noopener" }));
      out.push(links);
    }
  }
  const warned = warningList(item.result?.warnings ?? [], false).list;
  if (warned) out.push(warned);
  const times = new Map((summary?.per_frame ?? []).map((r) => [r.frame, r.time_s]));
  out.push(frameTable(item.frames, times));
  return out;
}

function summaryTable(dimensions: Summary["dimensions"], unit: string): HTMLTableElement {
  const table = el("table", "", { id: "video-summary", class: "data" });
  table.append(el("caption", `Dimensions over the measured frames (${unit})`));
  const head = el("tr");
  for (const h of ["Dimension", "Median", "Min", "Max", "Spread", "Spread / median"]) head.append(el("th", h, { scope: "col" }));
  table.append(el("thead"), el("tbody"));
  table.tHead!.append(head);
  for (const d of DIMENSIONS) {
    const stats = dimensions[d];
    if (!stats) continue;
    const tr = el("tr", "", { "data-dimension": d });
    tr.append(el("th", capital(d), { scope: "row" }));
    for (const k of ["median", "min", "max", "spread"] as const) tr.append(el("td", stats[k].toFixed(2), { "data-stat": k }));
    const rel = stats.relative_spread;
    tr.append(el("td", rel === null ? "–" : `${(rel * 100).toFixed(2)} %`, { "data-stat": "relative_spread" }));
    table.tBodies[0].append(tr);
  }
  return table;
}

function frameTable(frames: Frame[], times: Map<number, number | undefined>): HTMLTableElement {
  const table = el("table", "", { id: "frame-results", class: "data" });
  table.append(el("caption", "Frames"));
  const head = el("tr");
  for (const h of ["Frame", "Time (s)", "State", "Width", "Height", "Depth", "Files or error"]) head.append(el("th", h, { scope: "col" }));
  table.append(el("thead"), el("tbody"));
  table.tHead!.append(head);
  for (const f of frames) {
    const tr = el("tr", "", { "data-frame": String(f.index) });
    const time = times.get(f.index);
    tr.append(el("th", String(f.index), { scope: "row" }), el("td", time === undefined ? "" : time.toFixed(3)),
      el("td", f.state));
    for (const d of DIMENSIONS) {
      const v = f.result?.dimensions[d];
      tr.append(el("td", v === undefined ? "" : `${v.toFixed(2)} ${f.result!.dimensions.unit}`, { "data-field": d }));
    }
    const last = el("td");
    if (f.error) {
      last.className = "error";
      last.textContent = capital(f.error) + (f.error.endsWith(".") ? "" : ".");
    }
    for (const [kind, text] of FRAME_LINKS) {
      if (!f.downloads[kind]) continue;
      last.append(Object.assign(el("a", text, { "aria-label": `Frame ${f.index}: download ${text}` }),
        { href: f.downloads[kind], rel: "noopener" }), " ");
    }
    tr.append(last);
    table.tBodies[0].append(tr);
  }
  return table;
}
