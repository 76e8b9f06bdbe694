// Step 1 of the page: photos chosen here are shown from the local file (decoded by the browser,
// upright by their EXIF orientation as the engine reads them) and streamed to POST /v1/uploads.
// A video is uploaded first, then shown frame by frame as the service decodes it (video.ts).

import { call, message } from "./api";
import { nameInput } from "./results-table";
import { state, type PhotoEntry } from "./state";
import type { Upload } from "./types";
import { describeVideo, isVideo, videoFrame, videoInfo } from "./video";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
let nextId = 1;

export class Photos {
  onChange: (what: "photos" | "front" | "side" | "mode") => void = () => {};

  constructor() {
    $<HTMLInputElement>("files").addEventListener("change", (e) => {
      const input = e.target as HTMLInputElement;
      // Decoded all at once, but each takes its place (the front photo, the side photo, the
      // next photo of a part) after the one chosen before it, whichever decodes first.
      let before = Promise.resolve();
      for (const file of Array.from(input.files ?? [])) before = this.add(file, before);
      input.value = "";
    });
    $<HTMLSelectElement>("front-photo").addEventListener("change", (e) => {
      state.front = Number((e.target as HTMLSelectElement).value) || null;
      this.onChange("front");
    });
    $<HTMLSelectElement>("side-photo").addEventListener("change", (e) => {
      state.side = Number((e.target as HTMLSelectElement).value) || null;
      this.onChange("side");
    });
    for (const radio of document.querySelectorAll<HTMLInputElement>("input[name=mode]")) {
      radio.addEventListener("change", () => {
        state.twoPhoto = radio.value === "two" && radio.checked;
        $("side-photo-row").hidden = !state.twoPhoto;
        if (state.twoPhoto && state.side === null) {
          state.side = state.photos.find((p) => p.id !== state.front && p.bitmap && !p.video)?.id ?? null;
        }
        this.render();
        this.onChange("mode");
      });
    }
  }

  /** List `file`, decode it and upload it. Resolves once it has taken its place, which it does
   *  only after `before` (the photo chosen before it) has: a video takes its own when the service
   *  has read it, a file that cannot be shown none. */
  private async add(file: File, before: Promise<void>): Promise<void> {
    const entry: PhotoEntry = {
      id: nextId++, name: file.name, bitmap: null, upload: null, status: "uploading…", video: null,
    };
    state.photos.push(entry);
    this.render();
    if (await isVideo(file).catch(() => false)) {
      void this.addVideo(entry, file);
      return before;
    }
    try {
      entry.bitmap = await createImageBitmap(file, { imageOrientation: "from-image" });
    } catch {
      // The service says what is wrong with a file it refuses (a JPEG cut short, a PDF), which
      // the browser cannot: ask it before blaming the browser.
      entry.status = "the browser cannot show this file; asking the service what it is…";
      this.render();
      try {
        await upload(file);
        entry.status = "this browser cannot show this file; use JPEG, PNG, WebP or BMP";
      } catch (err) {
        entry.status = `refused: ${message(err)}`;
      }
      this.render();
      return before;
    }
    await before.catch(() => undefined); // whatever went wrong there, this photo still takes its place
    const firstFront = state.front === null;
    if (firstFront) state.front = entry.id;
    else if (state.twoPhoto && state.side === null) state.side = entry.id;
    this.render();
    this.onChange(firstFront ? "front" : "photos");
    void this.upload(entry, file);
  }

  private async upload(entry: PhotoEntry, file: File): Promise<void> {
    try {
      entry.upload = await upload(file);
      entry.status = "uploaded";
    } catch (err) {
      entry.status = `upload failed: ${message(err)}`;
    }
    this.render();
    this.onChange("photos");
  }

  /** Upload, have the service read it, show frame 0: the frame picker takes it from there. */
  private async addVideo(entry: PhotoEntry, file: File): Promise<void> {
    entry.video = { info: null, frame: 0 };
    try {
      entry.upload = await upload(file);
    } catch (err) {
      entry.status = `upload failed: ${message(err)}`;
      return this.render();
    }
    entry.status = "uploaded; the service is reading the video…";
    this.render();
    try {
      entry.video.info = await videoInfo(entry.upload.id);
      entry.status = `uploaded, ${describeVideo(entry.video.info)}`;
      this.render();
      entry.bitmap = await videoFrame(entry.upload.id, 0);
    } catch (err) {
      entry.status = `not a video the service can measure: ${message(err)}`;
      return this.render();
    }
    const firstFront = state.front === null;
    if (firstFront) state.front = entry.id;
    this.render();
    this.onChange(firstFront ? "front" : "photos");
  }

  render(): void {
    $("photo-list").replaceChildren(...state.photos.map((p) => {
      const li = document.createElement("li");
      const size = p.bitmap && !p.video ? ` (${p.bitmap.width} × ${p.bitmap.height})` : "";
      li.textContent = `${p.name}${p.video ? " (video)" : size}: ${p.status}`;
      li.className = /^(upload failed|not a video|this browser|refused)/.test(p.status) ? "error" : "";
      return li;
    }));
    for (const [id, chosen] of [["front-photo", state.front], ["side-photo", state.side]] as const) {
      const select = $<HTMLSelectElement>(id);
      // A video is measured in single-photo mode: it is never a side photo.
      select.replaceChildren(...state.photos.filter((p) => p.bitmap && (id === "front-photo" || !p.video)).map((p) => {
        const option = new Option(p.video ? `${p.name} (video)` : p.name, String(p.id), false, p.id === chosen);
        return option;
      }));
      if (chosen === null) select.value = "";
    }
  }
}

/** Stream `file` to POST /v1/uploads (stored and probed by the service). */
export async function upload(file: File): Promise<Upload> {
  const form = new FormData();
  form.append("file", file, file.name);
  const stored = (await (await call("/v1/uploads", { method: "POST", body: form })).json()) as Upload;
  nameInput(stored.reference, file.name); // the job's table shows the file's name
  return stored;
}
