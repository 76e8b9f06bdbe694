// Calls to the PrismCloud API on this origin, with the key in the X-API-Key header, and the
// API's error answers turned into sentences a person can act on.

const KEY_NAME = "prism.apiKey"; // sessionStorage: gone when the tab closes, never in a URL

export function savedKey(): string | null {
  return sessionStorage.getItem(KEY_NAME);
}

export function saveKey(key: string | null): void {
  if (key === null) sessionStorage.removeItem(KEY_NAME);
  else sessionStorage.setItem(KEY_NAME, key);
}

export class ApiError extends Error {
  /** The problem document the service answered with, when it sent one. */
  constructor(message: string, readonly status: number, readonly problem?: Problem) {
    super(message);
  }
}

/** An error answer: RFC 9457 problem details (application/problem+json). `type` is stable. */
export interface Problem {
  type?: string;
  title?: string;
  status?: number;
  detail?: string;
  instance?: string;
  errors?: { pointer?: string; parameter?: string; header?: string; detail?: string }[];
}

function where(pointer: string): string {
  // "/items/0/points/p1" -> "scan 1, points, p1" (RFC 6901: "~1" is "/", "~0" is "~")
  const parts = pointer.split("/").slice(1).map((p) => p.replace(/~1/g, "/").replace(/~0/g, "~"));
  if (parts[0] === "items" && parts.length > 1) parts.splice(0, 2, `scan ${Number(parts[1]) + 1}`);
  // "views/1" (several photos of one part) -> "photo 2", as the page numbers them
  const view = parts.indexOf("views");
  if (view >= 0 && /^\d+$/.test(parts[view + 1] ?? "")) parts.splice(view, 2, `photo ${Number(parts[view + 1]) + 1}`);
  return parts.join(", ");
}

function sentence(text: string): string {
  return text.charAt(0).toUpperCase() + text.slice(1) + (/[.!?]$/.test(text) ? "" : ".");
}

export function plainWords(status: number, problem: Problem | undefined): string {
  if (status === 401) return "The API key was not accepted. Check it and log in again.";
  if (status === 413) return "The file is larger than the service accepts.";
  if (status === 503) return "The service is busy or one of its stores is down; try again shortly.";
  const errors = problem?.errors ?? [];
  if (errors.length) {
    const msgs = errors.map((e) => {
      const place = e.pointer ? where(e.pointer) : (e.parameter ?? e.header ?? "");
      return (place ? `${place}: ` : "") + (e.detail ?? "invalid");
    });
    return `The service refused the request. ${msgs.join("; ")}`;
  }
  if (typeof problem?.detail === "string" && problem.detail) return sentence(problem.detail);
  return `The service answered with an error (HTTP ${status}).`;
}

/** The API's URL for `path` ("/v1/..."): beside the page's folder, so that the page and the API
 * may sit together under any prefix a proxy gives them (the page is <prefix>/app/). */
export function apiUrl(path: string): string {
  return new URL(path.replace(/^\//, ""), new URL("../", document.baseURI)).href;
}

export async function call(path: string, init: RequestInit = {}, key = savedKey()): Promise<Response> {
  const headers = new Headers(init.headers);
  if (key) headers.set("X-API-Key", key);
  let response: Response;
  try {
    response = await fetch(apiUrl(path), { ...init, headers, cache: "no-store" });
  } catch {
    throw new ApiError("Could not reach the service. Check the connection and try again.", 0);
  }
  if (!response.ok) {
    let problem: Problem | undefined;
    try {
      problem = (await response.json()) as Problem;
    } catch {
      problem = undefined;
    }
    throw new ApiError(plainWords(response.status, problem), response.status, problem);
  }
  return response;
}

const sleep = (ms: number) => new Promise((resolve) => window.setTimeout(resolve, ms));
const WAIT_LIMIT_MS = 180_000; // a worker busy with long scans may take a while to get to it

/** GET `path`, asking again while the API answers 202 (a worker is still on it); past the wait
 *  limit, an ApiError saying `tooLong`. */
export async function whenReady(path: string, tooLong: string): Promise<Response> {
  const deadline = Date.now() + WAIT_LIMIT_MS;
  for (;;) {
    const response = await call(path);
    if (response.status !== 202) return response;
    if (Date.now() > deadline) throw new ApiError(tooLong, 202);
    const after = Number(response.headers.get("Retry-After")) || 1;
    await sleep(Math.min(after, 5) * 1000);
  }
}

export async function getJson<T>(path: string, key?: string): Promise<T> {
  return (await call(path, {}, key)).json() as Promise<T>;
}

export async function postJson<T>(path: string, body: unknown): Promise<T> {
  const init = { method: "POST", body: JSON.stringify(body), headers: { "Content-Type": "application/json" } };
  return (await call(path, init)).json() as Promise<T>;
}

export function message(err: unknown): string {
  return err instanceof Error ? err.message : String(err);
}
