// Station mode: the chosen station verified with a reference part of known size
// (POST /v1/stations/{id}/verifications: its photos, one per placement, its size W,D,H and a
// tolerance), the figures a factory's measurement system analysis asks for shown in a table (bias
// with its 95 % interval, repeatability, placements within their 3 sigma, %GRR) and the verdict in
// words; the station's row then states it. A refusal is said at the photo or field at fault.

import { ApiError, call, message } from "./api";
import type { Station, Verification } from "./types";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;

const FIELDS: Record<string, string> = { reference: "Reference size", tolerance: "Tolerance", photo: "Photos" };

/** A refused verification in words, at the photo (by its file name) or the field at fault. */
export function verifyRefusal(err: unknown, names: string[]): string {
  if (!(err instanceof ApiError) || err.status !== 422 || !err.problem?.errors?.length) return message(err);
  const lines = err.problem.errors.map((e) => {
    const [field = "", index] = (e.pointer ?? "").split("/").slice(1);
    let where = FIELDS[field] ?? field;
    const name = index !== undefined && /^\d+$/.test(index) ? names[Number(index)] : undefined;
    if (name) where = `Photo ${Number(index) + 1} (${name})`;
    let detail = e.detail ?? "invalid";
    if (name && detail.startsWith(`${name}: `)) detail = detail.slice(name.length + 2);
    return where ? `${where}: ${detail}` : detail;
  });
  return `The verification was refused. ${lines.join("; ")}`;
}

const mm = (v: number, digits = 3) => `${v >= 0 ? "+" : "−"}${Math.abs(v).toFixed(digits)}`;

/** The verification as a table: a row per dimension, as `prism station verify` prints it. */
export function verificationTable(v: Verification): HTMLTableElement {
  const table = document.createElement("table");
  table.className = "results";
  table.id = "verify-table";
  const caption = Object.assign(document.createElement("caption"), {
    textContent: `Errors are measured minus reference, mm; %GRR = 6 × repeatability / 2T × 100` });
  const head = document.createElement("tr");
  for (const title of ["Dimension", "Reference", "Bias", "95 % interval", "Repeatability", "Within 3 sigma", "%GRR",
    "Verdict"]) {
    head.append(Object.assign(document.createElement("th"), { scope: "col", textContent: title }));
  }
  const body = document.createElement("tbody");
  for (const [name, d] of Object.entries(v.dimensions)) {
    const inside = d.within_3_sigma.filter(Boolean).length;
    const cells = [name, d.reference_mm.toFixed(2), mm(d.bias_mm), `[${mm(d.bias_ci95_mm[0])}, ${mm(d.bias_ci95_mm[1])}]`,
      d.repeatability_mm.toFixed(3), `${inside} of ${d.within_3_sigma.length}`,
      d.grr_percent === null ? "–" : `${d.grr_percent.toFixed(1)} %`, d.verified ? "ok" : "fails"];
    const tr = document.createElement("tr");
    tr.dataset.dimension = name;
    for (const c of cells) tr.append(Object.assign(document.createElement("td"), { textContent: c }));
    if (!d.verified) tr.lastElementChild!.className = "error";
    body.append(tr);
  }
  table.append(caption, Object.assign(document.createElement("thead"), {}), body);
  table.tHead!.append(head);
  return table;
}

/** "Verified on 2026-12-06 with a 70 × 45 × 30 mm reference (width × depth × height), 7 placements". */
export function verdictLine(v: Verification): string {
  const ref = Object.values(v.reference_mm).map((x) => `${x}`).join(" × ");
  const tol = v.tolerance_mm === null ? "no tolerance" : `tolerance ± ${v.tolerance_mm} mm`;
  return `${v.verified ? "Verified" : "Not verified"} on ${v.date.slice(0, 10)} with a ${ref} mm reference ` +
    `(width × depth × height), ${v.photos.length} placements, ${tol}.`;
}

export class StationVerify {
  station: () => Station | null = () => null;
  /** After a verification is stored: the stations are read again (their rows state it). */
  onDone: (said: string) => Promise<void> = async () => {};

  constructor() {
    $("verify-run").addEventListener("click", () => void this.run());
  }

  private async run(): Promise<void> {
    const button = $<HTMLButtonElement>("verify-run");
    const [status, error, result] = [$("verify-status"), $("verify-error"), $("verify-result")];
    error.textContent = "";
    result.replaceChildren();
    const station = this.station();
    const photos = [...($<HTMLInputElement>("verify-photos").files ?? [])];
    const reference = $<HTMLInputElement>("verify-reference").value.trim();
    const tolerance = $<HTMLInputElement>("verify-tolerance").value.trim();
    if (!station) { error.textContent = "Choose a station first (its row's Use)."; return; }
    if (!reference) { error.textContent = "Give the reference part's true size W,D,H in mm, e.g. 70,45,30."; return; }
    if (photos.length < 5) {
      error.textContent = `Choose the reference part's photos, one per placement: 5 at least (${photos.length} chosen).`;
      return;
    }
    const form = new FormData();
    for (const p of photos) form.append("photo", p, p.name);
    form.append("reference", reference);
    if (tolerance) form.append("tolerance", tolerance);
    button.disabled = true;
    status.textContent = `Measuring ${photos.length} photos of the reference part…`;
    try {
      const done = (await (await call(`/v1/stations/${station.id}/verifications`, { method: "POST", body: form }))
        .json()) as Verification;
      const verdict = Object.assign(document.createElement("p"), { id: "verify-verdict", textContent: verdictLine(done) });
      verdict.className = done.verified ? "verify-ok" : "error";
      const failures = document.createElement("ul");
      for (const f of done.decided_by) failures.append(Object.assign(document.createElement("li"), { textContent: f }));
      result.append(verdict, verificationTable(done), failures,
        Object.assign(document.createElement("p"), { className: "help", textContent: `Rule: ${done.rule}` }));
      status.textContent = "";
      await this.onDone(`${done.verified ? "Verified" : "Not verified"}: ${station.name ?? station.id.slice(0, 8)}.`);
    } catch (err) {
      status.textContent = "Not stored.";
      error.textContent = verifyRefusal(err, photos.map((p) => p.name));
    } finally {
      button.disabled = false;
    }
  }
}
