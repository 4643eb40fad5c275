// The service's REST API as the page uses it: the key (sessionStorage, sent as a Bearer header, never in a
// URL), JSON calls whose errors keep the API's {"error": {code, message, field}}, and downloads fetched
// with the header and saved through an object URL.

export const API = "/api/v1";
const KEY_ITEM = "shockbench.key";

/** The key of this browser tab's session, or null. */
export function storedKey() {
  return sessionStorage.getItem(KEY_ITEM);
}

export function storeKey(key) {
  sessionStorage.setItem(KEY_ITEM, key);
}

export function forgetKey() {
  sessionStorage.removeItem(KEY_ITEM);
}

/** An API error: HTTP status, the error's code and one-line message, and the field it names (or null). */
export class ApiFailure extends Error {
  constructor(status, code, message, field) {
    super(message);
    this.status = status;
    this.code = code;
    this.field = field ?? null;
  }
}

function authHeaders(extra = {}) {
  const key = storedKey();
  return key ? { ...extra, Authorization: `Bearer ${key}` } : extra;
}

async function failure(response) {
  let body = null;
  try {
    body = await response.json();
  } catch {
    // not JSON: the status says enough
  }
  const error = body?.error ?? {};
  return new ApiFailure(
    response.status,
    error.code ?? "http_" + response.status,
    error.message ?? `${response.status} ${response.statusText}`,
    error.field,
  );
}

/**
 * Call the API. `path` starts below /api/v1 (e.g. "/bench") or is a full /api/v1/... link from a response.
 * `body`: an object (sent as JSON) or FormData. Answers the parsed JSON (null for an empty body); throws
 * ApiFailure on an error status.
 */
export async function api(path, { method = "GET", body, signal } = {}) {
  const url = path.startsWith(API) ? path : API + path;
  const init = { method, headers: authHeaders({ Accept: "application/json" }), signal };
  if (body instanceof FormData) {
    init.body = body;
  } else if (body !== undefined) {
    init.body = JSON.stringify(body);
    init.headers["Content-Type"] = "application/json";
  }
  const response = await fetch(url, init);
  if (!response.ok) throw await failure(response);
  const text = await response.text();
  return text ? JSON.parse(text) : null;
}

/** A download as a Blob (the Bearer header sent; an <a href> could not send it). */
export async function fetchBlob(link) {
  const response = await fetch(link, { headers: authHeaders() });
  if (!response.ok) throw await failure(response);
  return response.blob();
}

/** Fetch `link` and save it under `filename` through a temporary object URL. */
export async function download(link, filename) {
  const blob = await fetchBlob(link);
  const url = URL.createObjectURL(blob);
  const a = document.createElement("a");
  a.href = url;
  a.download = filename;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10_000);
}

/** A promise resolved after `ms` milliseconds, or rejected when `signal` aborts. */
export function pause(ms, signal) {
  return new Promise((resolve, reject) => {
    const timer = setTimeout(resolve, ms);
    signal?.addEventListener("abort", () => {
      clearTimeout(timer);
      reject(signal.reason);
    });
  });
}

/** Poll a job every 0.5 s until it succeeded, failed or was cancelled; `onUpdate` sees each state. */
export async function waitForJob(link, onUpdate, signal) {
  for (;;) {
    const job = await api(link, { signal });
    onUpdate?.(job);
    if (["succeeded", "failed", "cancelled"].includes(job.status)) return job;
    await pause(500, signal);
  }
}
