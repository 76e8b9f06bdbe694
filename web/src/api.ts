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
  constructor(message: string, readonly status: number) {
    super(message);
  }
}

type Detail = string | { loc?: (string | number)[]; msg?: string }[] | undefined;

function where(loc: (string | number)[] = []): string {
  // ["body", "items", 0, "points", "p1"] -> "scan 1, points, p1"
  const parts = loc.filter((p) => p !== "body").map(String);
  if (parts[0] === "items" && parts.length > 1) parts.splice(0, 2, `scan ${Number(parts[1]) + 1}`);
  return parts.join(", ");
}

export function plainWords(status: number, detail: Detail): string {
  if (status === 401) return "The API key was not accepted. Check it and log in again.";
  if (status === 413) return "The file is larger than the service accepts.";
  if (status === 503) return "The service is busy or one of its stores is down; try again shortly.";
  if (Array.isArray(detail)) {
    const msgs = detail.map((d) => (d.loc?.length ? `${where(d.loc)}: ` : "") + (d.msg ?? "invalid"));
    return `The service refused the request. ${msgs.join("; ")}`;
  }
  if (typeof detail === "string" && detail) return detail.charAt(0).toUpperCase() + detail.slice(1) + ".";
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
    let detail: Detail;
    try {
      detail = (await response.json()).detail;
    } catch {
      detail = undefined;
    }
    throw new ApiError(plainWords(response.status, detail), response.status);
  }
  return response;
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
