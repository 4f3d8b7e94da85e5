// The REST client: JSON in and out, errors turned into ApiError with the
// server's readable `detail`.

export class ApiError extends Error {
  constructor(status, error, detail) {
    super(detail || error || `HTTP ${status}`);
    this.status = status;
    this.error = error;
    this.detail = detail || error || `the server answered HTTP ${status}`;
  }
}

/**
 * Where the HMI is served: this module is at `<base>/js/api.js`, so the base
 * is one folder up. Behind a reverse proxy the server may sit under a
 * sub-path (`[server] base_path`, e.g. `/scada/`); every URL the HMI asks
 * for is made from this base, never from the site's root.
 */
export const BASE = new URL('../', import.meta.url);

/** The URL of an API path (`/api/...`) under the HMI's base. */
export function apiUrl(path) {
  return new URL(path.replace(/^\//, ''), BASE).href;
}

let onUnauthorized = () => {};
/** Called when any request answers 401 (the session ended). */
export function setUnauthorizedHandler(f) { onUnauthorized = f; }

import { noteActivity } from './session.js';

/**
 * One request. `opts.user`: the user asked for it (a click), so it is
 * activity even if the page reports itself hidden. `opts.timeoutMs`: give
 * up (as a network error) when no answer came by then.
 */
export async function api(method, path, body, opts = {}) {
  const init = { method, credentials: 'same-origin', headers: { Accept: 'application/json' } };
  // Polls of a hidden screen are not the user's activity: they must not keep
  // an unwatched session alive (docs/ACCESS.md).
  const hidden = !opts.user && document.visibilityState !== 'visible';
  if (hidden) init.headers['X-Gridscada-Background'] = '1';
  if (opts.timeoutMs) init.signal = AbortSignal.timeout(opts.timeoutMs);
  if (body !== undefined) {
    init.headers['Content-Type'] = 'application/json';
    init.body = JSON.stringify(body);
  }
  let resp;
  try {
    resp = await fetch(apiUrl(path), init);
  } catch (e) {
    throw new ApiError(0, 'network', `cannot reach the server (${e.message})`);
  }
  // Any answer from a logged-in session counts as its activity.
  if (resp.status !== 401 && !hidden) noteActivity();
  const text = await resp.text();
  let data = null;
  if (text) {
    try { data = JSON.parse(text); } catch { data = null; }
  }
  if (!resp.ok) {
    if (resp.status === 401 && path !== '/api/session') onUnauthorized();
    const detail = data && (data.detail || data.error);
    throw new ApiError(resp.status, data && data.error, detail || `${method} ${path} failed: HTTP ${resp.status}`);
  }
  return data;
}

export const get = (p) => api('GET', p);
export const post = (p, b = {}) => api('POST', p, b);
export const put = (p, b) => api('PUT', p, b);
export const patch = (p, b) => api('PATCH', p, b);
export const del = (p, b) => api('DELETE', p, b);

/** Builds a query string, skipping empty values. */
export function qs(params) {
  const u = new URLSearchParams();
  for (const [k, v] of Object.entries(params)) {
    if (v === undefined || v === null || v === '') continue;
    u.set(k, String(v));
  }
  const s = u.toString();
  return s ? `?${s}` : '';
}

export const enc = encodeURIComponent;
