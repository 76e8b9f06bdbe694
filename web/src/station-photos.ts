// Station mode, step 2: a folder of photos (chosen, or dropped with its subfolders) or loose
// photos, uploaded as the page uploads any photo (POST /v1/uploads, a few at a time), each checked
// against the station's camera by the size the service read from it, then ONE job with an item
// per photo, `{"image": "upload:...", "station": ID}` (no points, no scale), followed by run.ts.
// Files that are not photos (a folder's .DS_Store, a notes.txt) are left out, and said so.

import { message } from "./api";
import { upload } from "./photos";
import { nameInput } from "./results-table";
import type { Station, Upload } from "./types";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
const PHOTO = /\.(jpe?g|png|webp|bmp|tiff?)$/i;
const AT_ONCE = 4; // uploads in flight: enough to fill the line, few enough to show progress

interface Entry {
  path: string; // its path in the folder dropped, or its name
  file: File;
  upload: Upload | null;
  status: "waiting" | "uploading" | "uploaded" | "failed";
  error: string;
}

/** What the station can measure: why not, or null. */
function misfit(e: Entry, station: Station | null): string | null {
  if (e.status === "failed") return e.error;
  const probe = e.upload?.probe;
  if (!probe || !station) return null;
  if (probe.error) return probe.error;
  if (probe.kind !== "image") return "not a photo";
  if (probe.width !== null && probe.height !== null
      && (probe.width !== station.image_width || probe.height !== station.image_height)) {
    return `${probe.width} × ${probe.height} px, the station's camera takes ${station.image_width} × ${station.image_height} px`;
  }
  return null;
}

/** Every file under a dropped entry (a folder read to its end, in the order readEntries gives). */
async function filesOf(entry: FileSystemEntry): Promise<{ path: string; file: File }[]> {
  if (entry.isFile) {
    const file = await new Promise<File>((ok, fail) => (entry as FileSystemFileEntry).file(ok, fail));
    return [{ path: entry.fullPath.replace(/^\//, ""), file }];
  }
  const reader = (entry as FileSystemDirectoryEntry).createReader();
  const found: { path: string; file: File }[] = [];
  for (;;) { // readEntries answers in chunks (100 in Chromium) until an empty one
    const chunk = await new Promise<FileSystemEntry[]>((ok, fail) => reader.readEntries(ok, fail));
    if (!chunk.length) return found;
    for (const child of chunk) found.push(...await filesOf(child));
  }
}

export class StationPhotos {
  private entries: Entry[] = [];
  private skipped: string[] = [];
  private submitted = false; // the list went as a job: the next photos start a new one
  station: () => Station | null = () => null;
  /** Submit the items as one job (run.ts), resolving once it is accepted. */
  submit: (items: { image: string; station: string }[], reference: string) => Promise<unknown> = async () => {};

  constructor() {
    for (const id of ["station-folder", "station-files"]) {
      $<HTMLInputElement>(id).addEventListener("change", (e) => {
        const input = e.target as HTMLInputElement;
        this.add([...(input.files ?? [])].map((file) => ({ path: file.webkitRelativePath || file.name, file })));
        input.value = "";
      });
    }
    const zone = $("drop-zone");
    zone.addEventListener("dragover", (e) => {
      e.preventDefault();
      if (e.dataTransfer) e.dataTransfer.dropEffect = "copy";
      zone.classList.add("over");
    });
    zone.addEventListener("dragleave", () => zone.classList.remove("over"));
    zone.addEventListener("drop", (e) => {
      e.preventDefault();
      zone.classList.remove("over");
      void this.dropped(e.dataTransfer);
    });
    $("station-submit").addEventListener("click", () => void this.run());
    $("station-clear").addEventListener("click", () => this.clear());
  }

  private async dropped(data: DataTransfer | null): Promise<void> {
    if (!data) return;
    // Entries first (they walk into folders); the plain file list when the browser gives none.
    const entries = [...data.items].map((i) => (i.kind === "file" ? i.webkitGetAsEntry() : null));
    const files = [...data.files];
    try {
      if (entries.some((e) => e !== null)) {
        const found = await Promise.all(entries.filter((e): e is FileSystemEntry => e !== null).map(filesOf));
        this.add(found.flat());
      } else {
        this.add(files.map((file) => ({ path: file.name, file })));
      }
    } catch (err) {
      $("station-run-error").textContent = `The folder could not be read: ${message(err)}`;
    }
  }

  clear(): void {
    this.entries = [];
    this.skipped = [];
    this.submitted = false;
    $("station-run-error").textContent = "";
    this.render();
  }

  /** Add the photos among `files` (sorted by path, numbers in order) and upload them. */
  add(files: { path: string; file: File }[]): void {
    if (this.submitted) this.clear();
    $("station-run-error").textContent = "";
    const known = new Set(this.entries.map((e) => `${e.path}:${e.file.size}`));
    const sorted = [...files].sort((a, b) => a.path.localeCompare(b.path, undefined, { numeric: true }));
    for (const { path, file } of sorted) {
      const base = path.split("/").pop() ?? path;
      if (base.startsWith(".") || !(PHOTO.test(base) || file.type.startsWith("image/"))) {
        this.skipped.push(path);
      } else if (!known.has(`${path}:${file.size}`)) {
        known.add(`${path}:${file.size}`);
        this.entries.push({ path, file, upload: null, status: "waiting", error: "" });
      }
    }
    this.render();
    for (let i = 0; i < AT_ONCE; i++) void this.uploadNext();
  }

  private async uploadNext(): Promise<void> {
    const list = this.entries;
    for (let e = list.find((x) => x.status === "waiting"); e; e = list.find((x) => x.status === "waiting")) {
      e.status = "uploading";
      try {
        e.upload = await upload(e.file);
        nameInput(e.upload.reference, e.path); // the job's table shows where in the folder it was
        e.status = "uploaded";
      } catch (err) {
        e.status = "failed";
        e.error = `upload failed: ${message(err)}`;
      }
      if (list !== this.entries) return; // cleared meanwhile
      this.render();
    }
  }

  /** Render the list and the button against the station chosen (called when it changes). */
  render(): void {
    const station = this.station();
    const count = (s: Entry["status"]) => this.entries.filter((e) => e.status === s).length;
    const left = count("waiting") + count("uploading");
    const refused = this.entries.filter((e) => misfit(e, station) !== null);
    const ready = this.entries.filter((e) => e.status === "uploaded" && !misfit(e, station));
    const parts: string[] = [];
    if (!this.entries.length) parts.push("No photos yet");
    else parts.push(`${this.entries.length} photo${this.entries.length > 1 ? "s" : ""}`);
    if (left) parts.push(`${count("uploaded") + count("failed")} of ${this.entries.length} uploaded`);
    else if (this.entries.length) parts.push("all uploaded");
    if (refused.length) parts.push(`${refused.length} cannot be measured on this station (see each photo)`);
    if (this.skipped.length) {
      const shown = this.skipped.slice(0, 3).join(", ") + (this.skipped.length > 3 ? ", …" : "");
      parts.push(`${this.skipped.length} other file${this.skipped.length > 1 ? "s" : ""} left out (${shown})`);
    }
    $("station-photos-summary").textContent = parts.join(" · ") + ".";
    $("station-photo-list").replaceChildren(...this.entries.map((e) => {
      const li = document.createElement("li");
      const why = misfit(e, station);
      li.textContent = `${e.path}: ${why ? `left out: ${why}` : e.status}`;
      if (why) li.className = "error";
      return li;
    }));
    $("station-photo-details").hidden = !this.entries.length;
    if (refused.length) $<HTMLDetailsElement>("station-photo-details").open = true;
    const button = $<HTMLButtonElement>("station-submit");
    button.textContent = !ready.length ? "Measure the photos"
      : `Measure ${ready.length} photo${ready.length > 1 ? "s" : ""}${station ? ` on ${station.name ?? "the station"}` : ""}`;
  }

  private async run(): Promise<void> {
    const error = $("station-run-error");
    error.textContent = "";
    const station = this.station();
    const left = this.entries.filter((e) => e.status === "waiting" || e.status === "uploading").length;
    if (!station) error.textContent = "Choose a station first (or add one above).";
    else if (!this.entries.length) error.textContent = "Add the photos first: drop a folder, or choose one.";
    else if (left) error.textContent = `Wait for ${left} photo${left > 1 ? "s" : ""} to finish uploading.`;
    else if (!station.has_plate) {
      error.textContent = `${station.name ?? "This station"} has no photo of the empty support: no part can be found `
        + "on it. Add the station again with its empty support.";
    }
    if (!station || !station.has_plate || !this.entries.length || left) return;
    const ready = this.entries.filter((e) => e.status === "uploaded" && !misfit(e, station));
    if (!ready.length) {
      error.textContent = "None of these photos can be measured on this station: see each photo.";
      return;
    }
    const button = $<HTMLButtonElement>("station-submit");
    button.disabled = true;
    try {
      const items = ready.map((e) => ({ image: e.upload!.reference, station: station.id }));
      await this.submit(items, `station ${station.name ?? station.id.slice(0, 8)}`);
      this.submitted = true;
    } catch (err) {
      // "scan 3, image: ..." names the photo too: the service numbers the items from 1 as the page does.
      error.textContent = message(err).replace(/\bscan (\d+)/g, (all, n: string) => {
        const e = ready[Number(n) - 1];
        return e ? `${all} (${e.path})` : all;
      });
    } finally {
      button.disabled = false;
    }
  }
}
