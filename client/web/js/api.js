// The HTTP API, with the bearer token when the server asks for one. Paths are relative to the
// page so the viewer also works behind a reverse proxy that mounts the server under a prefix.

const TOKEN_KEY = 'lightcast.token';

/** An answer of the server other than 2xx: its status and JSON error body. */
export class ApiError extends Error {
  constructor(status, body) {
    super(body.message || `HTTP ${status}`);
    this.status = status;
    this.kind = body.error || 'http_error';
    this.field = body.field || null;
  }
}

/** The server could not be reached at all (down, restarting, network gone). */
export class Unreachable extends Error {}

export function token() {
  return localStorage.getItem(TOKEN_KEY) || '';
}

export function setToken(value) {
  if (value) localStorage.setItem(TOKEN_KEY, value);
  else localStorage.removeItem(TOKEN_KEY);
}

/** A `#token=…` fragment is taken once and removed from the address bar. */
export function takeTokenFromFragment() {
  const match = location.hash.match(/token=([^&]+)/);
  if (match) {
    setToken(decodeURIComponent(match[1]));
    history.replaceState(null, '', location.pathname + location.search);
  }
}

export function url(path) {
  return new URL(path, document.baseURI);
}

export function wsUrl(path) {
  const u = url(path);
  u.protocol = u.protocol === 'https:' ? 'wss:' : 'ws:';
  return u;
}

/** fetch with the token; returns the Response of a 2xx, throws ApiError or Unreachable. */
export async function request(method, path, { json, body, headers = {}, keepalive } = {}) {
  const h = { ...headers };
  const t = token();
  if (t) h.Authorization = `Bearer ${t}`;
  if (json !== undefined) {
    h['Content-Type'] = 'application/json';
    body = JSON.stringify(json);
  }
  let response;
  try {
    response = await fetch(url(path), { method, headers: h, body, keepalive });
  } catch (e) {
    throw new Unreachable(`the server at ${location.host} cannot be reached (${e.message})`);
  }
  if (!response.ok) {
    let errorBody;
    try {
      errorBody = await response.json();
    } catch {
      errorBody = { message: `HTTP ${response.status} ${response.statusText}` };
    }
    throw new ApiError(response.status, errorBody);
  }
  return response;
}

export async function getJson(path) {
  return (await request('GET', path)).json();
}

export async function sendJson(method, path, json) {
  const response = await request(method, path, { json });
  return response.status === 204 ? null : response.json();
}
