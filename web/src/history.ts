// The user's recent jobs (GET /v1/jobs, without their items), newest first, each with a button
// that opens it (the whole job is read then).

import { getJson, message } from "./api";
import type { Job, JobList } from "./types";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
const LIMIT = 20;

export class History {
  onOpen: (job: Job) => void = () => {};

  constructor() {
    $("refresh-jobs").addEventListener("click", () => void this.load());
  }

  async load(): Promise<void> {
    const body = document.querySelector<HTMLTableSectionElement>("#jobs tbody")!;
    try {
      const { jobs } = await getJson<JobList>(`/v1/jobs?limit=${LIMIT}&items=false`);
      body.replaceChildren(...jobs.map((job) => this.row(job)));
      if (!jobs.length) body.replaceChildren(messageRow("No jobs yet."));
    } catch (err) {
      body.replaceChildren(messageRow(message(err)));
    }
  }

  private async open(id: string): Promise<void> {
    try {
      this.onOpen(await getJson<Job>(`/v1/jobs/${id}`));
    } catch (err) {
      $("form-error").textContent = message(err);
    }
  }

  private row(job: Job): HTMLTableRowElement {
    const tr = document.createElement("tr");
    tr.dataset.job = job.id;
    const created = new Date(job.created_at).toLocaleString();
    for (const text of [created, job.id.slice(0, 8), job.state, `${job.progress} %`, `${job.items_done ?? 0} of ${job.item_count}`]) {
      tr.append(Object.assign(document.createElement("td"), { textContent: text }));
    }
    const open = document.createElement("button");
    open.type = "button";
    open.textContent = "Open";
    open.setAttribute("aria-label", `Open job ${job.id.slice(0, 8)} (${job.state})`);
    open.addEventListener("click", () => void this.open(job.id));
    const td = document.createElement("td");
    td.append(open);
    tr.append(td);
    return tr;
  }
}

function messageRow(text: string): HTMLTableRowElement {
  const tr = document.createElement("tr");
  const td = Object.assign(document.createElement("td"), { textContent: text, colSpan: 6 });
  tr.append(td);
  return tr;
}
