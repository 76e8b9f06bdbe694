// A scan of several photos of one part measured as ONE box (the result's `joint` block): how
// many photos were used, above the dimensions; after them, a table of the photos, each used one
// with its click fit and what it measures alone, each left out with the reason. The photos left
// out are also among the scan's warnings (the worker puts them there), shown as every warning
// is. Such a scan makes no cloud: no 3D view and no fit overlay are shown for it.

import type { Dimension, Item, Joint, Result } from "./types";

const DIMENSIONS: Dimension[] = ["width", "height", "depth"];

export function jointOf(item: Item): Joint | null {
  return item.result?.joint ?? null;
}

const el = <K extends keyof HTMLElementTagNameMap>(tag: K, text = "", attrs: Record<string, string> = {}) => {
  const node = document.createElement(tag);
  node.textContent = text;
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  return node;
};

/** "Measured as one box from 2 of 3 photos; 1 left out (see the warnings)." */
export function jointLine(joint: Joint): HTMLElement {
  const used = joint.views.length;
  const total = used + joint.left_out.length;
  const left = joint.left_out.length;
  return el("p", `Measured as one box from ${used} of ${total} photos` +
    (left ? `; ${left} left out (see the warning${left > 1 ? "s" : ""}).` : "."), { id: "joint-views" });
}

/** The focal length fitted to every photo at once, with its 1-sigma when it was fitted. */
export function jointFocal(r: Result, joint: Joint): string {
  const f = r.focal_px ? Math.round(r.focal_px) : null;
  if (f === null) return "";
  return joint.focal_std_px === null ? `${f} px, given` : `${f} ± ${Math.round(joint.focal_std_px)} px, fitted to every photo`;
}

/** A row per photo in the order sent: used (its clicks' fit, what it measures alone) or left out (why). */
export function jointTable(joint: Joint, unit: string): HTMLElement {
  const table = el("table", "", { class: "data", id: "joint-table" });
  table.append(el("caption", "The photos of this part"));
  const head = el("tr");
  for (const title of ["Photo", "", "Clicks off the box (RMS)", "Alone: width × height × depth"]) {
    head.append(el("th", title, { scope: "col" }));
  }
  const thead = el("thead");
  thead.append(head);
  table.append(thead);
  const used = joint.views.map((v) => ({ index: v.index, name: v.name, cells: ["used", `${v.click_rms_px.toFixed(2)} px`,
    `${DIMENSIONS.map((d) => v.alone[d].toFixed(1)).join(" × ")} ${unit}`] }));
  const left = joint.left_out.map((o) => ({ index: o.index, name: o.name, cells: ["left out", o.reason] }));
  const body = el("tbody");
  for (const row of [...used, ...left].sort((a, b) => a.index - b.index)) {
    const tr = el("tr", "", { "data-view": String(row.index) });
    tr.append(el("th", row.name, { scope: "row" }));
    // A reason takes the room of the figures a photo left out has none of.
    row.cells.forEach((text, i) => tr.append(el("td", text, row.cells.length === 2 && i === 1 ? { colspan: "2" } : {})));
    body.append(tr);
  }
  table.append(body);
  return table;
}
