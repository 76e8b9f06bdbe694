// A scan's warnings, shown as warnings (each in an amber frame with a number, not a bare bullet)
// and tied to the figures they qualify, so that a number a warning casts doubt on is never shown
// bold and alone: the figure is drawn plain, flagged "⚠ n" and described by the warning
// (aria-describedby), and the warning sits right under the dimensions, saying which it is about.
//
// The service's warnings are sentences; one that names a dimension ("... costs about 81 % on the
// depth") qualifies that dimension, one that names none (an edge not found, perspective not
// corrected, points found with a modest confidence) qualifies all three.

import type { Dimension } from "./types";

export const DIMENSIONS: Dimension[] = ["width", "height", "depth"];

/** The dimensions a warning's text is about: those it names, or all of them. */
export function qualified(text: string): Dimension[] {
  const named = DIMENSIONS.filter((d) => new RegExp(`\\b${d}s?\\b`, "i").test(text));
  return named.length ? named : [...DIMENSIONS];
}

export interface Warned {
  /** The list to show (null when there are no warnings). */
  list: HTMLElement | null;
  /** Per dimension, the ids and numbers of the warnings that qualify it. */
  of: Record<Dimension, { id: string; n: number }[]>;
}

/** The warnings as a numbered, framed list; with `dims`, each tagged with the figures it qualifies. */
export function warningList(texts: string[], dims: boolean): Warned {
  const of: Warned["of"] = { width: [], height: [], depth: [] };
  if (!texts.length) return { list: null, of };
  const list = document.createElement("ol");
  list.className = "warnings";
  list.id = "warnings";
  list.setAttribute("aria-label", "Warnings");
  texts.forEach((text, i) => {
    const n = i + 1;
    const li = document.createElement("li");
    li.className = "warning";
    li.id = `warning-${n}`;
    const tag = document.createElement("span");
    tag.className = "warning-tag";
    if (dims) {
      const about = qualified(text);
      li.dataset.dims = about.join(" ");
      for (const d of about) of[d].push({ id: li.id, n });
      // One about every figure is flagged beside each of them; its tag needs no names.
      tag.textContent = about.length === DIMENSIONS.length ? `⚠ ${n}:` : `⚠ ${n} · ${about.join(", ")}:`;
    } else {
      tag.textContent = `⚠ ${n}:`;
    }
    li.append(tag, " ", text);
    list.append(li);
  });
  return { list, of };
}

/** The flag beside a figure: "⚠ 1, 3", naming the warnings that qualify it. */
export function flag(refs: { id: string; n: number }[]): HTMLElement {
  const dd = document.createElement("dd");
  dd.className = "flag";
  if (refs.length) {
    dd.textContent = `⚠ ${refs.map((r) => r.n).join(", ")}`;
    dd.title = `See warning${refs.length > 1 ? "s" : ""} ${refs.map((r) => r.n).join(", ")} below`;
  }
  return dd;
}
