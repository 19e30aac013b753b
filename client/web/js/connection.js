// One streaming session: creates it, opens its WebSocket with a ticket, and keeps it alive.
// When the socket drops it reconnects by itself (with backoff); when the session is gone
// (deleted, the server restarted, or behind the router its replica gone) it creates a new one
// with the last known parameters.
// A ping every few seconds notices links that died silently (sleep, NAT timeouts).

import { ApiError, Unreachable, request, sendJson, wsUrl } from './api.js';

const MIN_BACKOFF_MS = 500;
const MAX_BACKOFF_MS = 8000;
const PING_EVERY_MS = 5000;
const SILENCE_LIMIT_MS = 15000;
// Answers to the old session's ticket request that start a new session: 404 (gone), 421 (it
// belongs to a replica this address does not reach) and the router's 502/503/504 for a replica
// that is gone or unready, which may never come back (a scale-in). Each attempt still waits out
// the backoff, so a cluster that is down is not flooded with new sessions.
const SESSION_LOST = new Set([404, 421, 502, 503, 504]);
// Refused parameters a new session drops, one per attempt, before it gives up and retries.
const MAX_REFUSED_FIELDS = 4;

/**
 * A copy of `params` without the field at `path`, which the server defaults; `null` when
 * `params` has no such field. The path joins keys with dots, and a key may hold dots itself
 * (`?gi.a.b=1` gives `gi` the key `a.b`, refused as `render.gi.a.b`): at each level the
 * longest run of parts that is a key is taken. An index (`position[0]`) drops the whole list.
 */
function withoutField(params, path) {
  const copy = structuredClone(params);
  const parts = path.split('.');
  // The key of `node` spelled by parts[i..end], as given or without its list index.
  const keyOf = (node, i, end) => {
    const joined = parts.slice(i, end).join('.');
    const bare = joined.replace(/(\[\d+\])+$/, '');
    return [joined, bare].find((k) => Object.hasOwn(node, k)) ?? null;
  };
  let node = copy;
  let i = 0;
  while (node && typeof node === 'object') {
    let end = parts.length;
    while (end > i && keyOf(node, i, end) === null) end--;
    if (end === i) return null;
    const key = keyOf(node, i, end);
    if (end === parts.length) {
      delete node[key];
      return copy;
    }
    node = node[key];
    i = end;
  }
  return null;
}

export class Connection {
  /**
   * `handlers`: onFrame(ArrayBuffer), onEvent(event), onSession(SessionInfo),
   * onStatus(state, message) with state one of connecting, live, reconnecting, unreachable,
   * unauthorized, stopped.
   */
  constructor(params, handlers) {
    this.params = params;
    this.handlers = handlers;
    this.sessionId = null;
    this.ws = null;
    this.backoff = MIN_BACKOFF_MS;
    // Bumped by start() and stop(): work begun under an older generation is abandoned.
    this.generation = 0;
    this.timer = null;
    this.watchdog = null;
  }

  start() {
    this.generation += 1;
    this.connect(this.generation);
  }

  /** Sends a control message; false when no socket is open (the caller may retry later). */
  send(message) {
    if (this.ws && this.ws.readyState === WebSocket.OPEN) {
      this.ws.send(JSON.stringify(message));
      return true;
    }
    return false;
  }

  /** Ends the session on the server (also when the page goes away). */
  stop() {
    this.generation += 1;
    this.dropSocket('viewer closed');
    clearTimeout(this.timer);
    if (this.sessionId) {
      this.deleteSession(this.sessionId);
      this.sessionId = null;
    }
    this.handlers.onStatus('stopped', 'stopped');
  }

  deleteSession(id) {
    request('DELETE', `v1/sessions/${encodeURIComponent(id)}`, { keepalive: true }).catch(() => {});
  }

  dropSocket(reason) {
    clearInterval(this.watchdog);
    const ws = this.ws;
    this.ws = null;
    if (ws) ws.close(1000, reason);
  }

  async connect(generation) {
    if (generation !== this.generation) return;
    this.handlers.onStatus('connecting', this.sessionId ? 'reconnecting to the session…' : 'starting a session…');
    let ws;
    try {
      const ticket = await this.ticket(generation);
      if (generation !== this.generation) return;
      const path = `v1/sessions/${encodeURIComponent(this.sessionId)}/stream?ticket=${encodeURIComponent(ticket)}`;
      ws = new WebSocket(wsUrl(path));
    } catch (e) {
      if (generation === this.generation) this.failed(e, generation);
      return;
    }
    ws.binaryType = 'arraybuffer';
    this.ws = ws;
    let closingReason = null;
    let lastMessage = performance.now();
    let nonce = 0;
    clearInterval(this.watchdog);
    this.watchdog = setInterval(() => {
      if (this.ws !== ws) return;
      if (performance.now() - lastMessage > SILENCE_LIMIT_MS) {
        // onclose does not fire for a socket we drop ourselves: reconnect from here.
        this.dropSocket('no answer');
        this.retry(`no word from the server for ${SILENCE_LIMIT_MS / 1000} s`, 'reconnecting', generation);
      } else if (ws.readyState === WebSocket.OPEN) {
        ws.send(JSON.stringify({ type: 'ping', nonce: ++nonce }));
      }
    }, PING_EVERY_MS);
    ws.onmessage = (message) => {
      if (this.ws !== ws) return;
      lastMessage = performance.now();
      if (typeof message.data !== 'string') {
        this.handlers.onFrame(message.data);
        return;
      }
      let event;
      try {
        event = JSON.parse(message.data);
      } catch {
        return;
      }
      if (event.type === 'hello' || event.type === 'updated') {
        this.params = event.session.params;
        this.handlers.onSession(event.session);
        if (event.type === 'hello') {
          this.backoff = MIN_BACKOFF_MS;
          this.handlers.onStatus('live', `live · session ${this.sessionId}`);
        }
      } else if (event.type === 'closing') {
        closingReason = event.reason;
      }
      this.handlers.onEvent(event);
    };
    ws.onclose = (close) => {
      if (this.ws !== ws) return;
      clearInterval(this.watchdog);
      this.ws = null;
      const reason = closingReason || close.reason || `connection lost (code ${close.code})`;
      if (closingReason && closingReason.startsWith('session')) {
        // The session was deleted or ended idle; a new one carries on with the same view.
        this.sessionId = null;
      }
      this.retry(`${reason}; reconnecting`, 'reconnecting', generation);
    };
  }

  /** A ticket for the current session, creating the session first when there is none. */
  async ticket(generation) {
    if (this.sessionId) {
      try {
        const t = await sendJson('POST', `v1/sessions/${encodeURIComponent(this.sessionId)}/ticket`);
        return t.ticket;
      } catch (e) {
        if (!(e instanceof ApiError) || !SESSION_LOST.has(e.status)) throw e;
        // Its replica may only be unreachable for a while: ask it to end the session (best
        // effort) so that it does not hold a slot there until it idles out.
        if (e.status !== 404) this.deleteSession(this.sessionId);
        this.sessionId = null;
      }
    }
    let created;
    for (let attempt = 0; ; attempt++) {
      try {
        created = await sendJson('POST', 'v1/sessions', this.params);
        break;
      } catch (e) {
        // A parameter the server refuses (one from the address, or a scene that went away
        // with a restarted server) would be refused again on every retry: say so, and ask
        // again with the server's default for that field.
        const refused = e instanceof ApiError && e.field && (e.status === 400 || e.status === 404);
        const dropped = refused ? withoutField(this.params, e.field) : null;
        if (dropped === null || attempt >= MAX_REFUSED_FIELDS) throw e;
        this.handlers.onEvent({ type: 'error', error: { error: e.kind, field: e.field, message: `${e.message}; using the server's default` } });
        this.params = dropped;
      }
    }
    if (generation !== this.generation) {
      // Stopped while the session was being created: it must not outlive the page.
      this.deleteSession(created.session.id);
      return null;
    }
    this.sessionId = created.session.id;
    this.params = created.session.params;
    this.handlers.onSession(created.session);
    return created.ticket.ticket;
  }

  failed(error, generation) {
    if (error instanceof ApiError && error.status === 401) {
      this.generation += 1;
      this.handlers.onStatus('unauthorized', error.message);
      return;
    }
    // A request the server refuses as malformed would be refused again on every retry.
    if (error instanceof ApiError && error.status === 400) {
      this.generation += 1;
      this.handlers.onStatus('stopped', `${error.message} (not retried: reload with other parameters)`);
      return;
    }
    this.retry(error.message, error instanceof Unreachable ? 'unreachable' : 'reconnecting', generation);
  }

  retry(message, state, generation) {
    if (generation !== this.generation) return;
    const wait = this.backoff;
    this.backoff = Math.min(this.backoff * 2, MAX_BACKOFF_MS);
    this.handlers.onStatus(state, `${message} · retrying in ${(wait / 1000).toFixed(1)} s`);
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.connect(generation), wait);
  }
}
