// Step 4 of the page: the batch of scans, submitting it as one job (POST /v1/jobs), following
// the job's state and progress until it ends, and cancelling it.

import { getJson, message, postJson } from "./api";
import { currentScan, hasMarks, type Scan, type SelectFrames } from "./scan";
import type { Settings } from "./settings";
import { FINAL, type Job, type ScanSpec } from "./types";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
const POLL_MS = 600;
const LIGHT_POLL_ITEMS = 50;
const WORDS: Record<string, string> = {
  queued: "Queued: waiting for a worker.", running: "Running.", succeeded: "Done.",
  completed_with_failures: "Done, with failures:", failed: "Failed.", cancelled: "Cancelled.",
};

export class Runner {
  private batch: Scan[] = [];
  private job: Job | null = null;
  private timer = 0;
  onAdded: () => void = () => {};
  onFinished: (job: Job) => void = () => {};

  constructor(private settings: () => Settings, private selectFrames: SelectFrames) {
    $("add-batch").addEventListener("click", () => this.guard(() => this.add()));
    $("submit").addEventListener("click", () => this.guard(() => this.submit()));
    $("cancel").addEventListener("click", () => this.guard(() => this.cancel()));
  }

  private async guard(action: () => unknown): Promise<void> {
    const error = $("form-error");
    error.textContent = "";
    try {
      await action();
    } catch (err) {
      error.textContent = message(err);
    }
  }

  private add(): void {
    this.batch.push(currentScan(this.settings(), this.selectFrames));
    this.renderBatch();
    this.onAdded();
  }

  private renderBatch(): void {
    $("batch").replaceChildren(...this.batch.map((scan, i) => {
      const li = document.createElement("li");
      const remove = document.createElement("button");
      remove.type = "button";
      remove.textContent = "Remove";
      remove.setAttribute("aria-label", `Remove scan ${i + 1} (${scan.label}) from the batch`);
      remove.addEventListener("click", () => {
        this.batch.splice(i, 1);
        this.renderBatch();
      });
      li.append(`Scan ${i + 1}: ${scan.label} `, remove);
      return li;
    }));
  }

  private async submit(): Promise<void> {
    const scans = this.batch.length && !hasMarks() ? [...this.batch]
      : [...this.batch, currentScan(this.settings(), this.selectFrames)];
    const button = $<HTMLButtonElement>("submit");
    button.disabled = true;
    try {
      const job = await postJson<Job>("/v1/jobs", { items: scans.map((s) => s.spec), client_reference: "web page" });
      this.batch = [];
      this.renderBatch();
      this.follow(job);
    } finally {
      button.disabled = false;
    }
  }

  /** Submit `items` as one job (station mode: an item per photo) and follow it. */
  async run(items: ScanSpec[], reference: string): Promise<Job> {
    window.clearTimeout(this.timer);
    const job = await postJson<Job>("/v1/jobs", { items, client_reference: reference });
    this.follow(job);
    return job;
  }

  /** Show `job` and poll it until it ends. */
  follow(job: Job): void {
    window.clearTimeout(this.timer);
    this.job = null;
    this.update(job);
  }

  private update(job: Job): void {
    const changed = this.job?.state !== job.state || this.job?.id !== job.id;
    this.job = job;
    const progress = $<HTMLProgressElement>("job-progress");
    progress.value = job.progress;
    // Progress counts frames for a video: say how many are measured so far.
    const frames = job.items.reduce((n, i) => n + i.frames.length, 0);
    const parts = [`${job.progress} %`];
    if (job.item_count > 1) parts.push(`${job.items_done} of ${job.item_count} scans`);
    if (frames) parts.push(`${frames} frames measured`);
    const left = remaining(job);
    if (left) parts.push(left);
    $("job-percent").textContent = parts.join(" · ");
    if (changed) {
      // The status region is read out: only when the state changes, not at every percent.
      const cancelled = job.items.filter((i) => i.state === "cancelled").length;
      let extra = "";
      let error = job.error;
      if ((job.state === "completed_with_failures" || job.state === "failed") && job.items_failed) {
        // Said in scans, as the page shows them; the job's own error counting items is left out.
        extra = ` ${job.items_failed} of ${job.item_count} scans failed` +
          (job.state === "failed" ? "." : ", the others were measured.");
        if (error && /^(all items failed|\d+ of \d+ items failed)$/.test(error)) error = null;
      }
      if (job.state === "cancelled") {
        extra = ` ${job.items_done} of ${job.item_count} scans had finished; ${cancelled} were not run.`;
      }
      $("job-state").textContent = `Job ${job.id.slice(0, 8)}: ${WORDS[job.state]}${extra}` +
        (error ? ` ${error.charAt(0).toUpperCase()}${error.slice(1)}.` : "");
    }
    $("cancel").hidden = FINAL.includes(job.state);
    if (FINAL.includes(job.state)) return this.onFinished(job);
    this.timer = window.setTimeout(() => void this.poll(job.id), POLL_MS);
  }

  private async poll(id: string): Promise<void> {
    try {
      // A large batch (a station's folder) is polled without its items, read once when it ends.
      const light = (this.job?.item_count ?? 0) > LIGHT_POLL_ITEMS;
      let job = await getJson<Job>(`/v1/jobs/${id}${light ? "?item_limit=0" : ""}`);
      if (light && FINAL.includes(job.state)) job = await getJson<Job>(`/v1/jobs/${id}`);
      if ($("form-error").textContent?.startsWith("Lost track")) $("form-error").textContent = "";
      this.update(job);
    } catch (err) {
      $("form-error").textContent = `Lost track of the job: ${message(err)} Retrying…`;
      this.timer = window.setTimeout(() => void this.poll(id), POLL_MS * 5);
    }
  }

  private async cancel(): Promise<void> {
    if (this.job) this.follow(await postJson<Job>(`/v1/jobs/${this.job.id}/cancel`, {}));
  }
}

/** "about 2 min left", from the progress made since the job started; "" while unknown. */
export function remaining(job: Job, now: number = Date.now()): string {
  if (FINAL.includes(job.state) || !job.started_at || job.progress <= 0) return "";
  const elapsed = (now - Date.parse(job.started_at)) / 1000;
  const left = Math.max(0, (elapsed * (100 - job.progress)) / job.progress);
  if (!Number.isFinite(left)) return "";
  if (left < 60) return `about ${Math.max(1, Math.round(left))} s left`;
  if (left < 3600) return `about ${Math.round(left / 60)} min left`;
  return `about ${(left / 3600).toFixed(1)} h left`;
}
