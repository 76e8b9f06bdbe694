// The job's table (GET /v1/jobs/{id}/results.json): a row per scan and per video frame, sortable
// by any column, filtered by text and verdict, failed scans first on demand, exported as the
// service's CSV (results.csv, fetched with the key), each row opening its scan in the result.
// An input the page uploaded is shown by its file name (the reference in its title), and each
// row's warnings come from the job's items (results.json has none).

import { apiUrl, call, getJson, message } from "./api";
import type { Job, ResultRow, ResultsTable, Verdict } from "./types";
import { badge, verdictText } from "./verdicts";
import { DIMENSIONS, qualified } from "./warnings";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;

type Key = (row: ResultRow) => string | number | null;
interface Column {
  id: string;
  title: string;
  key: Key;
  cell: (row: ResultRow) => string | Node;
  numeric?: boolean;
}

// Worst first when sorted ascending: what an engineer looks for.
const VERDICT_ORDER: Record<string, number> = { fail: 0, uncertain: 1, pass: 2 };
const n = (v: unknown): number | null => (typeof v === "number" && Number.isFinite(v) ? v : null);

function dimension(d: "width" | "height" | "depth"): Column {
  return {
    id: d, title: `${d.charAt(0).toUpperCase()}${d.slice(1)}`, numeric: true, key: (r) => n(r[d]),
    cell: (r) => {
      const v = n(r[d]);
      if (v === null) return "";
      const s = n(r[`${d}_sigma`]);
      return `${v.toFixed(2)}${s === null ? "" : ` ± ${s.toFixed(2)}`} ${r.unit ?? ""}`.trim();
    },
  };
}

/** File names of the uploads the page made, by reference ("upload:..."): the table's inputs. */
const inputNames = new Map<string, string>();

export function nameInput(reference: string, name: string): void {
  inputNames.set(reference, name);
}

const inputName = (r: ResultRow): string => {
  const ref = String(r.input ?? "");
  return inputNames.get(ref) ?? ref;
};

/** Each row's warnings ("item:frame"), from the job's items and frames. */
let rowWarnings = new Map<string, string[]>();
const warningsOf = (r: ResultRow): string[] => rowWarnings.get(`${r.item}:${r.frame ?? ""}`) ?? [];

function warningsCell(r: ResultRow): string | Node {
  const list = warningsOf(r);
  if (!list.length) return "";
  const ol = document.createElement("ol");
  ol.className = "row-warnings";
  for (const text of list) ol.append(Object.assign(document.createElement("li"), { textContent: `⚠ ${text}` }));
  return ol;
}

const COLUMNS: Column[] = [
  { id: "scan", title: "Scan", key: (r) => r.item * 1e6 + (r.frame ?? -1) + 1,
    cell: (r) => `${r.item + 1}${r.frame === null ? "" : `, frame ${r.frame}`}` },
  { id: "input", title: "Input", key: inputName, cell: inputName },
  { id: "state", title: "State", key: (r) => r.state,
    cell: (r) => (r.error ? `${r.state}: ${r.error}` : r.state) },
  dimension("width"), dimension("height"), dimension("depth"),
  { id: "verdict", title: "Verdict", key: (r) => (r.verdict ? VERDICT_ORDER[r.verdict] : 3),
    cell: (r) => (r.verdict ? badge(r.verdict) : "") },
  { id: "warnings", title: "Warnings", key: (r) => warningsOf(r).length || null, cell: warningsCell },
  { id: "points", title: "Points", numeric: true, key: (r) => n(r.cloud_points),
    cell: (r) => n(r.cloud_points)?.toLocaleString("en") ?? "" },
  { id: "loss", title: "Point loss", numeric: true, key: (r) => n(r.point_loss),
    cell: (r) => { const v = n(r.point_loss); return v === null ? "" : `${(v * 100).toFixed(2)} %`; } },
];

/** A station's job: each row's station verification as the item stands (with its date when a
 *  verification stands), the camera's shift, and "re-verify" when that move asks for it. */
const STATION: Column = {
  id: "station", title: "Station", key: (r) => (r.station_verification === null ? null : String(r.station_verification)),
  cell: (r) => {
    if (r.station_verification === null || r.station_verification === undefined) return "";
    const px = n(r.camera_shift_px), shift = n(r.camera_shift_mm);
    const day = typeof r.station_verification_date === "string" ? r.station_verification_date : null;
    const status = r.station_verification === "verified" && day ? `verified on ${day}` : String(r.station_verification);
    return `${status}${px === null ? "" : ` · camera moved ${px.toFixed(1)} px`}` +
      `${shift === null ? "" : ` (${shift.toFixed(1)} mm)`}${r.station_reverify === true ? " · re-verify" : ""}`;
  },
};

const failed = (r: ResultRow) => r.verdict === "fail" || r.state === "failed";

export class ResultsTableView {
  onOpen: (item: number, frame: number | null) => void = () => {};
  private table: ResultsTable | null = null;
  private sort: { column: string; ascending: boolean } = { column: "scan", ascending: true };
  private current: string | null = null;

  constructor() {
    $("table-filter").addEventListener("input", () => this.render());
    $("table-verdict").addEventListener("change", () => this.render());
    $("failed-first").addEventListener("change", () => this.render());
    $("results-csv").addEventListener("click", (e) => {
      e.preventDefault();
      void this.download();
    });
  }

  /** Read the job's table and show it when the job has more than one row (a batch, a video),
   *  or `always` (a station's job: its table is the result, however many photos). */
  async load(job: Job, always = false): Promise<void> {
    const section = $("table-section");
    this.table = null;
    section.hidden = true;
    if (!always && job.item_count < 2 && !job.items.some((i) => i.frames.length)) return;
    rowWarnings = new Map();
    for (const item of job.items) {
      rowWarnings.set(`${item.index}:`, item.result?.warnings ?? []);
      for (const f of item.frames) rowWarnings.set(`${item.index}:${f.index}`, f.result?.warnings ?? []);
    }
    try {
      const table = await getJson<ResultsTable>(`/v1/jobs/${job.id}/results.json`);
      this.table = table;
      const csv = $<HTMLAnchorElement>("results-csv");
      csv.href = apiUrl(`/v1/jobs/${job.id}/results.csv`);
      csv.download = `${job.id.slice(0, 8)}-results.csv`;
      section.hidden = false;
      this.render();
    } catch (err) {
      section.hidden = false;
      $("table-count").textContent = `The job's table could not be read: ${message(err)}`;
    }
  }

  /** Outline the row shown in the result. */
  mark(item: number, frame: number | null): void {
    this.current = `${item}:${frame ?? ""}`;
    for (const tr of document.querySelectorAll<HTMLTableRowElement>("#results-table tbody tr")) {
      tr.classList.toggle("current", tr.dataset.row === this.current);
    }
  }

  /** The columns: with the Station column when a row was measured on a station. */
  private columns(): Column[] {
    const station = this.table?.rows.some((r) => r.station_verification !== null && r.station_verification !== undefined);
    return station ? [...COLUMNS.slice(0, 7), STATION, ...COLUMNS.slice(7)] : COLUMNS;
  }

  /** The rows as the controls want them: filtered, sorted, failed ones first if asked. */
  rows(): ResultRow[] {
    if (!this.table) return [];
    const text = $<HTMLInputElement>("table-filter").value.trim().toLowerCase();
    const verdict = $<HTMLSelectElement>("table-verdict").value;
    const column = this.columns().find((c) => c.id === this.sort.column) ?? COLUMNS[0];
    const sign = this.sort.ascending ? 1 : -1;
    const rows = this.table.rows.filter((r) => {
      if (verdict === "none" && r.verdict) return false;
      if (verdict === "failed" && r.state !== "failed") return false;
      if (verdict && !["none", "failed"].includes(verdict) && r.verdict !== verdict) return false;
      if (!text) return true;
      const words = [r.input, inputName(r), r.state, r.error, r.verdict, r.client_reference, `scan ${r.item + 1}`,
        r.station_verification, ...warningsOf(r)];
      return words.some((w) => w !== null && w !== undefined && String(w).toLowerCase().includes(text));
    });
    const compare = (a: ResultRow, b: ResultRow): number => {
      const [x, y] = [column.key(a), column.key(b)];
      if (x === y) return 0;
      if (x === null) return 1; // unknown values last, whichever the direction
      if (y === null) return -1;
      return (x < y ? -1 : 1) * sign;
    };
    const first = $<HTMLInputElement>("failed-first").checked;
    return rows.sort((a, b) => (first ? Number(failed(b)) - Number(failed(a)) : 0) || compare(a, b)
      || a.item - b.item || (a.frame ?? -1) - (b.frame ?? -1));
  }

  private render(): void {
    if (!this.table) return;
    const head = document.createElement("tr");
    for (const c of this.columns()) {
      const th = document.createElement("th");
      th.scope = "col";
      const button = document.createElement("button");
      button.type = "button";
      button.textContent = c.title;
      button.dataset.sort = c.id;
      if (this.sort.column === c.id) {
        th.setAttribute("aria-sort", this.sort.ascending ? "ascending" : "descending");
        button.textContent += this.sort.ascending ? " ▲" : " ▼";
      }
      button.setAttribute("aria-label", `Sort by ${c.title.toLowerCase()}`);
      button.addEventListener("click", () => {
        this.sort = { column: c.id, ascending: this.sort.column === c.id ? !this.sort.ascending : true };
        this.render();
        document.querySelector<HTMLButtonElement>(`#results-table th button[data-sort="${c.id}"]`)?.focus();
      });
      th.append(button);
      head.append(th);
    }
    head.append(Object.assign(document.createElement("th"), { scope: "col", textContent: "Open" }));
    $("results-table").querySelector("thead")!.replaceChildren(head);
    const rows = this.rows();
    $("results-table").querySelector("tbody")!.replaceChildren(...rows.map((r) => this.row(r)));
    $("table-count").textContent = `${rows.length} of ${this.table.rows.length} rows shown` +
      (this.table.verdicts ? ` · pass ${this.table.verdicts.pass ?? 0}, fail ${this.table.verdicts.fail ?? 0}, ` +
        `uncertain ${this.table.verdicts.uncertain ?? 0}` : "");
  }

  private row(r: ResultRow): HTMLTableRowElement {
    const tr = document.createElement("tr");
    tr.dataset.row = `${r.item}:${r.frame ?? ""}`;
    tr.dataset.verdict = r.verdict ?? "";
    if (r.verdict) tr.classList.add(`verdict-${r.verdict}`);
    tr.classList.add(`state-${r.state}`);
    if (tr.dataset.row === this.current) tr.classList.add("current");
    for (const c of this.columns()) {
      const td = document.createElement("td");
      td.dataset.col = c.id;
      if (c.numeric) td.className = "num";
      const dv = ["width", "height", "depth"].includes(c.id) ? r[`${c.id}_verdict`] : null;
      if (typeof dv === "string") {
        td.classList.add(`verdict-${dv}`);
        const dev = n(r[`${c.id}_deviation_mm`]);
        td.title = `${dv}${dev === null ? "" : `, deviation ${dev >= 0 ? "+" : ""}${dev.toFixed(2)} mm`}`;
      }
      td.append(c.cell(r));
      // A figure a warning qualifies is flagged here too, as in the result (warnings.ts).
      const dim = DIMENSIONS.find((d) => d === c.id);
      const warned = dim !== undefined && warningsOf(r).some((w) => qualified(w).includes(dim));
      if (warned && td.textContent) {
        td.classList.add("warned");
        td.append(Object.assign(document.createElement("span"), { className: "dim-warned", textContent: " ⚠",
          title: "A warning of this scan is about this figure" }));
      }
      if (c.id === "input" && inputName(r) !== String(r.input ?? "")) td.title = String(r.input);
      if (c.id === "station" && (r.station_verification !== "verified" || r.station_reverify === true) &&
        td.textContent) td.classList.add("warned");
      if (typeof dv === "string") {
        // The dimension's own verdict as a symbol and (for screen readers) a word, not colour alone.
        const mark = Object.assign(document.createElement("span"), { className: "dim-verdict", textContent:
          ` ${verdictText(dv as Verdict).split(" ")[0]}` });
        mark.setAttribute("aria-hidden", "true");
        td.append(mark, Object.assign(document.createElement("span"), { className: "sr-only", textContent: ` (${dv})` }));
      }
      tr.append(td);
    }
    const open = document.createElement("button");
    open.type = "button";
    open.textContent = "Open";
    const what = `scan ${r.item + 1}${r.frame === null ? "" : ` frame ${r.frame}`}`;
    open.setAttribute("aria-label", `Open ${what} in the result`);
    open.addEventListener("click", () => this.onOpen(r.item, r.frame));
    const td = document.createElement("td");
    td.append(open);
    tr.append(td);
    return tr;
  }

  /** The service's CSV of the job, fetched with the key (a plain link would go without it). */
  private async download(): Promise<void> {
    const link = $<HTMLAnchorElement>("results-csv");
    if (!this.table) return;
    try {
      const blob = await (await call(`/v1/jobs/${this.table.job_id}/results.csv`)).blob();
      const a = document.createElement("a");
      a.href = URL.createObjectURL(blob);
      a.download = link.download;
      document.body.append(a);
      a.click();
      a.remove();
      window.setTimeout(() => URL.revokeObjectURL(a.href), 10_000);
    } catch (err) {
      $("table-count").textContent = `The CSV could not be downloaded: ${message(err)}`;
    }
  }
}
