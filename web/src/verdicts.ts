// A verdict against the nominal size, shown in words and a symbol as well as a colour (the
// colour alone would leave out anyone who does not see it), in the result, the 3D view's labels
// and the job's table alike.

import type { DimensionVerdict, Verdict } from "./types";

const WORDS: Record<Verdict, string> = { pass: "✓ Pass", fail: "✗ Fail", uncertain: "? Uncertain" };

export function verdictText(v: Verdict): string {
  return WORDS[v] ?? v;
}

/** A badge: "✓ Pass" in green, "✗ Fail" in red, "? Uncertain" in amber. */
export function badge(v: Verdict, tag: "span" | "strong" = "span"): HTMLElement {
  const el = document.createElement(tag);
  el.className = `verdict verdict-${v}`;
  el.dataset.verdict = v;
  el.textContent = verdictText(v);
  return el;
}

/** "+0.31 mm (nominal 120.00 ± 3.00 mm)": the deviation and the limits it is judged against. */
export function deviationText(d: DimensionVerdict): string {
  const sign = d.deviation_mm >= 0 ? "+" : "−";
  return `${sign}${Math.abs(d.deviation_mm).toFixed(2)} mm (nominal ${d.nominal_mm.toFixed(2)} ± ` +
    `${d.tolerance_mm.toFixed(2)} mm)`;
}
