// The table of points under the photo: each point's place in words and its coordinates as
// labelled number fields, so points can be read by a screen reader and typed in as well as clicked.

import { describe, faceChoice, photoOf, sequence } from "./points";
import { state } from "./state";
import type { Point, PointName } from "./types";

let built = "";

export function renderPointTable(set: (name: PointName, p: Point) => void): void {
  const body = document.querySelector<HTMLTableSectionElement>("#point-table tbody")!;
  // One photo: every point is on it, and the Photo column says nothing (hidden, narrower rows).
  document.getElementById("point-table")!.classList.toggle("one-photo", !state.twoPhoto);
  const names = sequence(state.extra, state.twoPhoto);
  const key = `${names.join()}|${state.twoPhoto}|${faceChoice()}`;
  if (key !== built) {
    built = key;
    body.replaceChildren(...names.map((n) => row(n, set)));
  }
  for (const name of names) {
    const p = state.marks[name];
    for (const [axis, i] of [["x", 0], ["y", 1]] as const) {
      const input = document.getElementById(`${name}-${axis}`) as HTMLInputElement;
      if (document.activeElement !== input) input.value = p ? String(p[i]) : "";
    }
    const tr = document.getElementById(`row-${name}`)!;
    tr.classList.toggle("placed", Boolean(p));
  }
}

function row(name: PointName, set: (name: PointName, p: Point) => void): HTMLTableRowElement {
  const tr = document.createElement("tr");
  tr.id = `row-${name}`;
  const label = name.toUpperCase();
  const cells = [label, describe(name, state.twoPhoto), photoOf(name, state.twoPhoto) === "front" ? "front" : "side"];
  for (const [i, text] of cells.entries()) {
    const cell = document.createElement(i === 0 ? "th" : "td");
    if (i === 0) cell.scope = "row";
    cell.textContent = text;
    if (i === 1) cell.title = text; // the whole place, where a narrow column cuts it short
    tr.append(cell);
  }
  const inputs = (["x", "y"] as const).map((axis) => {
    const input = document.createElement("input");
    input.type = "number";
    input.step = "any";
    input.id = `${name}-${axis}`;
    input.setAttribute("aria-label", `${label} ${axis} (pixels)`);
    const td = document.createElement("td");
    td.append(input);
    tr.append(td);
    return input;
  });
  const commit = () => {
    const [x, y] = inputs.map((i) => i.valueAsNumber);
    if (Number.isFinite(x) && Number.isFinite(y)) set(name, [x, y]);
  };
  inputs.forEach((i) => i.addEventListener("change", commit));
  return tr;
}
