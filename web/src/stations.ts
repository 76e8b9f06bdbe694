// Station mode, step 1: the tenant's stations (GET /v1/stations) with what an engineer checks
// before trusting one (camera, board, the support plane's fit, whether the empty support is
// stored), the one the photos are measured on, a new one from its station.json or calibrated by
// the service from its photos (POST /v1/stations, JSON or multipart), and deleting one. Each row
// states the station's verification (verified on DATE with bias and repeatability, or not
// verified: station-verify.ts runs one) and its capability (mm per px, the smallest part and tolerance).
// A refused calibration is said in words, at the file at fault ("Plane photo (plane.jpg): ...").

import { ApiError, call, getJson, message } from "./api";
import type { Station, StationList } from "./types";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
const CHOSEN = "prism.station"; // sessionStorage: the station chosen in this tab

/** "line 1 (3f2a9c1b)", or the id's start alone. */
export function stationLabel(s: Station): string {
  return s.name ? `${s.name} (${s.id.slice(0, 8)})` : `station ${s.id.slice(0, 8)}`;
}

function boardText(s: Station): string {
  const b = s.board;
  const kind = b.type === "chessboard" ? "Chessboard" : "ChArUco";
  const squares = `${b.squares_x ?? "?"} × ${b.squares_y ?? "?"} squares`;
  return `${kind}, ${squares} of ${b.square_mm ?? "?"} mm`;
}

function cameraText(s: Station): string {
  const c = s.calibration;
  const how = c.source === "camera" ? "given camera.json"
    : `calibrated on ${Array.isArray(c.views) ? c.views.length : "its"} views of the board`;
  const rms = typeof c.rms_px === "number" ? `, RMS ${c.rms_px.toFixed(2)} px` : "";
  return `${s.image_width} × ${s.image_height} px, f ${s.camera.fx.toFixed(0)} px (${how}${rms})`;
}

/** "verified on 2026-12-06" or "not verified" (short: the row stays one line on a laptop; the
 *  bias and repeatability are in its title). */
function verificationText(s: Station): string {
  const v = s.verification;
  return v?.status === "verified" && v.date ? `verified on ${v.date.slice(0, 10)}` : "not verified";
}

function capabilityText(s: Station): string {
  const c = s.capability;
  if (!c) return "";
  return `${c.mm_per_px.near.toFixed(2)}–${c.mm_per_px.far.toFixed(2)} mm/px; parts ≥ ${c.min_part_mm.toFixed(0)} mm, ` +
    `± ${c.min_tolerance_mm.toFixed(2)} mm`;
}

function planeText(s: Station): string {
  return `${s.plane_rms_px.toFixed(2)} px RMS over ${s.plane_corners} corners; camera ${s.camera_height_mm.toFixed(0)} mm above`;
}

/** The field names of POST /v1/stations as a person calls them. */
const FIELDS: Record<string, string> = {
  board: "Board", plane: "Plane photo", calibration: "Calibration photos", camera: "Camera",
  plate: "Empty support photo",
};

/** A refusal of a new station in words, each error at the file it is about. */
export function refusal(err: unknown, files: Record<string, string[]> = {}): string {
  if (!(err instanceof ApiError) || err.status !== 422 || !err.problem?.errors?.length) return message(err);
  const lines = err.problem.errors.map((e) => {
    const [field = "", ...rest] = (e.pointer ?? "").split("/").slice(1);
    const k = /^\d+$/.test(rest[0] ?? "") ? Number(rest.shift()) : 0;
    const name = files[field]?.[k];
    let where = FIELDS[field] ?? (field ? `station.json, ${[field, ...rest].join("/")}` : "");
    if (field === "calibration" && name) where = `Calibration photo ${k + 1}`;
    if (name) where += ` (${name})`;
    if (FIELDS[field] && rest.length) where += `, ${rest.join("/")}`;
    let detail = e.detail ?? "invalid";
    if (name && detail.startsWith(`${name}: `)) detail = detail.slice(name.length + 2); // named once
    return where ? `${where}: ${detail}` : detail;
  });
  return `The station was refused. ${lines.join("; ")}`;
}

export class Stations {
  /** The stations listed, newest first. */
  list: Station[] = [];
  onChoose: (station: Station | null) => void = () => {};
  private sent: Record<string, string[]> = {}; // the files of the last request, by field: named in its refusal

  constructor() {
    $("refresh-stations").addEventListener("click", () => void this.load());
    $("store-station").addEventListener("click", () => void this.busy("store-station", () => this.storeJson()));
    $("calibrate-station").addEventListener("click", () => void this.busy("calibrate-station", () => this.calibrate()));
  }

  /** The station chosen, if it is still listed. */
  get chosen(): Station | null {
    const id = sessionStorage.getItem(CHOSEN);
    return this.list.find((s) => s.id === id) ?? null;
  }

  choose(id: string | null): void {
    if (id) sessionStorage.setItem(CHOSEN, id);
    else sessionStorage.removeItem(CHOSEN);
    this.render();
    this.onChoose(this.chosen);
  }

  /** Read the list again; `done` (what was just done) is said before the count. */
  async load(done = ""): Promise<void> {
    const status = $("station-status");
    try {
      this.list = (await getJson<StationList>("/v1/stations")).stations;
      const count = this.list.length ? `${this.list.length} station${this.list.length > 1 ? "s" : ""}.`
        : "No station yet: add one below.";
      status.textContent = `${done} ${count}`.trim();
      if (!this.list.length) ($<HTMLDetailsElement>("new-station")).open = true;
    } catch (err) {
      status.textContent = `The stations could not be read: ${message(err)}`;
    }
    // The only station, or the newest when none was chosen: chosen for the user.
    if (!this.chosen && this.list.length) sessionStorage.setItem(CHOSEN, this.list[0].id);
    this.render();
    this.onChoose(this.chosen);
  }

  private render(): void {
    const chosen = this.chosen;
    const body = document.querySelector<HTMLTableSectionElement>("#stations tbody")!;
    body.replaceChildren(...this.list.map((s) => {
      const tr = document.createElement("tr");
      tr.dataset.station = s.id;
      if (s === chosen) tr.classList.add("current");
      const use = Object.assign(document.createElement("input"), { type: "radio", name: "station", value: s.id,
        checked: s === chosen });
      use.setAttribute("aria-label", `Use ${stationLabel(s)}`);
      use.addEventListener("change", () => this.choose(s.id));
      const name = document.createElement("td");
      name.append(s.name ?? "(no name)", " ", Object.assign(document.createElement("code"), { textContent: s.id.slice(0, 8),
        title: s.id }));
      const plate = s.has_plate ? "stored" : "none: no part can be found";
      const cells: (string | Node)[] = [use, name, new Date(s.created_at).toLocaleString(), cameraText(s),
        boardText(s), planeText(s), plate, verificationText(s), capabilityText(s)];
      for (const c of cells) {
        const td = document.createElement("td");
        td.append(c);
        tr.append(td);
      }
      const [plateCell, verifiedCell] = [tr.children[6] as HTMLElement, tr.children[7] as HTMLElement];
      if (!s.has_plate) plateCell.className = "error";
      verifiedCell.dataset.col = "verification";
      verifiedCell.title = s.verification?.text ?? "not verified: no verification with a reference part yet";
      const capability = tr.children[8] as HTMLElement;
      capability.dataset.col = "capability";
      if (s.capability) {
        capability.title = `mm per px at the support's near and far edge; the smallest part and tolerance ± T it ` +
          `holds (${s.capability.rule})`;
      }
      // not verified: its measurements are warned so; said here before any photo is sent
      if (s.verification?.status !== "verified") verifiedCell.className = "error";
      const remove = Object.assign(document.createElement("button"), { type: "button", textContent: "Delete" });
      remove.setAttribute("aria-label", `Delete ${stationLabel(s)}`);
      remove.addEventListener("click", () => void this.remove(s));
      const td = document.createElement("td");
      td.append(remove);
      tr.append(td);
      return tr;
    }));
  }

  private async remove(s: Station): Promise<void> {
    $("station-error").textContent = "";
    if (!window.confirm(`Delete ${stationLabel(s)}? Jobs already queued on it will fail.`)) return;
    let done = "";
    try {
      await call(`/v1/stations/${s.id}`, { method: "DELETE" });
      done = `Deleted ${stationLabel(s)}.`;
    } catch (err) {
      $("station-error").textContent = message(err);
    }
    if (sessionStorage.getItem(CHOSEN) === s.id) sessionStorage.removeItem(CHOSEN);
    await this.load(done);
  }

  private async busy(button: string, action: () => Promise<Station>): Promise<void> {
    const b = $<HTMLButtonElement>(button);
    $("station-error").textContent = "";
    b.disabled = true;
    try {
      const made = await action();
      sessionStorage.setItem(CHOSEN, made.id);
      for (const id of ["station-json", "cal-board", "cal-plane", "cal-photos", "cal-camera", "cal-plate", "station-name"]) {
        $<HTMLInputElement>(id).value = "";
      }
      $<HTMLDetailsElement>("new-station").open = false;
      await this.load(`Stored ${stationLabel(made)}; the photos are measured on it.`);
    } catch (err) {
      $("station-status").textContent = "Not stored.";
      $("station-error").textContent = refusal(err, this.sent);
    } finally {
      b.disabled = false;
    }
  }

  private path(): string {
    const name = $<HTMLInputElement>("station-name").value.trim();
    return `/v1/stations${name ? `?name=${encodeURIComponent(name)}` : ""}`;
  }

  private async storeJson(): Promise<Station> {
    const file = $<HTMLInputElement>("station-json").files?.[0];
    if (!file) throw new Error("Choose the station.json file first.");
    $("station-status").textContent = `Storing ${file.name}…`;
    this.sent = {};
    const init = { method: "POST", body: file, headers: { "Content-Type": "application/json" } };
    return (await (await call(this.path(), init)).json()) as Station;
  }

  private async calibrate(): Promise<Station> {
    const files = (id: string) => [...($<HTMLInputElement>(id).files ?? [])];
    const [board, plane, photos, camera, plate] = ["cal-board", "cal-plane", "cal-photos", "cal-camera", "cal-plate"]
      .map(files);
    if (!board.length) throw new Error("Choose the board's board.json first.");
    if (!plane.length) throw new Error("Choose the plane photo: the board flat on the support, the camera in its place.");
    if (!photos.length && !camera.length) {
      throw new Error("Choose the calibration photos (the board in several poses), or the camera's camera.json.");
    }
    const form = new FormData();
    const add = (field: string, list: File[]) => list.forEach((f) => form.append(field, f, f.name));
    add("board", board);
    add("plane", plane);
    add("calibration", photos);
    add("camera", camera);
    add("plate", plate);
    const names = (list: File[]) => list.map((f) => f.name);
    this.sent = { board: names(board), plane: names(plane), calibration: names(photos), camera: names(camera),
      plate: names(plate) };
    $("station-status").textContent = `Calibrating from ${plane.length + photos.length + plate.length} photos…`;
    return (await (await call(this.path(), { method: "POST", body: form })).json()) as Station;
  }
}
