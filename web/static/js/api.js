// The REST API (service/openapi.json), same origin: the session is the
// HttpOnly cookie POST /api/v1/sessions sets, so no token is kept in script.

export class ApiError extends Error {
  // retryAfter: seconds, from a 503's Retry-After (0 when it has none).
  constructor(status, message, retryAfter = 0) {
    super(message);
    this.status = status;
    this.retryAfter = retryAfter;
  }
}

// Called with the ApiError of any 401 (the session ended): the app shows sign-in.
let onUnauthorized = () => {};
export function setUnauthorizedHandler(fn) { onUnauthorized = fn; }

// One request. body: an object (sent as JSON), a Blob/File (sent raw, as
// contentType) or undefined. Answers the parsed JSON, null for 204, or throws ApiError with
// the server's {"error": "..."} message.
export async function api(method, path, body, { signal, quiet401 = false, contentType, onResponse } = {}) {
  const init = { method, credentials: 'same-origin', signal, headers: {} };
  if (body instanceof Blob) {
    init.body = body;
    init.headers['Content-Type'] = contentType || body.type || 'application/octet-stream';
  } else if (body !== undefined) {
    init.body = JSON.stringify(body);
    init.headers['Content-Type'] = 'application/json';
  }
  let res;
  try {
    res = await fetch(path, init);
  } catch (e) {
    if (e.name === 'AbortError') throw e;
    throw new ApiError(0, 'The server cannot be reached: ' + e.message);
  }
  if (onResponse && res.ok) onResponse(res);
  if (res.status === 204) return null;
  const text = await res.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch { /* not JSON: said below */ }
  if (!res.ok) {
    const message = (data && typeof data.error === 'string') ? data.error
      : `${res.status} ${res.statusText || 'error'}`;
    const wait = Number(res.headers.get('Retry-After'));
    const err = new ApiError(res.status, message, Number.isFinite(wait) && wait > 0 ? Math.min(wait, 60) : 0);
    if (res.status === 401 && !quiet401) onUnauthorized(err);
    throw err;
  }
  if (data === null && text) throw new ApiError(res.status, 'The server answered something that is not JSON.');
  return data;
}

export const get = (path, opts) => api('GET', path, undefined, opts);
// A GET of a list that comes in pages: { items, next }, next the path of the
// page after (from the Link header's rel="next"), or null on the last.
export async function getPage(path, opts) {
  let next = null;
  const items = await api('GET', path, undefined, { ...opts, onResponse: (res) => {
    const m = /<([^>]*)>\s*;\s*rel="next"/.exec(res.headers.get('Link') || '');
    next = m ? m[1] : null;
  } });
  return { items, next };
}
export const post = (path, body, opts) => api('POST', path, body, opts);
export const put = (path, body, opts) => api('PUT', path, body, opts);
export const del = (path, opts) => api('DELETE', path, undefined, opts);
