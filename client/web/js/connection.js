// One streaming session: creates it, opens its WebSocket with a ticket, and keeps it alive.
// When the socket drops it reconnects by itself (with backoff); when the session is gone
// (deleted, or the server restarted) it creates a new one with the last known parameters.

import { ApiError, Unreachable, request, sendJson, wsUrl } from './api.js';

const MIN_BACKOFF_MS = 500;
const MAX_BACKOFF_MS = 8000;

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
    this.stopped = false;
    this.timer = null;
  }

  start() {
    this.stopped = false;
    this.connect();
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
    this.stopped = true;
    clearTimeout(this.timer);
    if (this.ws) this.ws.close(1000, 'viewer closed');
    if (this.sessionId) {
      request('DELETE', `v1/sessions/${this.sessionId}`, { keepalive: true }).catch(() => {});
      this.sessionId = null;
    }
    this.handlers.onStatus('stopped', 'stopped');
  }

  async connect() {
    if (this.stopped) return;
    this.handlers.onStatus('connecting', this.sessionId ? 'reconnecting to the session…' : 'starting a session…');
    let ticket;
    try {
      ticket = await this.ticket();
    } catch (e) {
      this.failed(e);
      return;
    }
    if (this.stopped) return;
    const ws = new WebSocket(wsUrl(`v1/sessions/${this.sessionId}/stream?ticket=${ticket}`));
    ws.binaryType = 'arraybuffer';
    this.ws = ws;
    let closingReason = null;
    ws.onmessage = (message) => {
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
      if (this.ws !== ws || this.stopped) return;
      this.ws = null;
      const reason = closingReason || close.reason || `connection lost (code ${close.code})`;
      if (closingReason === 'session deleted') {
        // Someone ended the session; a new one carries on with the same view.
        this.sessionId = null;
      }
      this.retry(`${reason}; reconnecting`);
    };
  }

  /** A ticket for the current session, creating the session first when there is none. */
  async ticket() {
    if (this.sessionId) {
      try {
        const t = await sendJson('POST', `v1/sessions/${this.sessionId}/ticket`);
        return t.ticket;
      } catch (e) {
        if (!(e instanceof ApiError) || e.status !== 404) throw e;
        this.sessionId = null;
      }
    }
    let created;
    try {
      created = await sendJson('POST', 'v1/sessions', this.params);
    } catch (e) {
      // The scene went away with the old session (e.g. a restarted server): fall back to the
      // server's default scene rather than retrying forever.
      if (!(e instanceof ApiError) || e.field !== 'render.scene') throw e;
      this.handlers.onEvent({ type: 'error', error: { error: e.kind, field: e.field, message: `${e.message}; using the default scene` } });
      this.params = { ...this.params, render: { ...this.params.render, scene: 'default' } };
      created = await sendJson('POST', 'v1/sessions', this.params);
    }
    this.sessionId = created.session.id;
    this.params = created.session.params;
    this.handlers.onSession(created.session);
    return created.ticket.ticket;
  }

  failed(error) {
    if (error instanceof ApiError && error.status === 401) {
      this.stopped = true;
      this.handlers.onStatus('unauthorized', error.message);
      return;
    }
    const what = error instanceof Unreachable ? 'unreachable' : 'reconnecting';
    this.retry(error.message, what);
  }

  retry(message, state = 'reconnecting') {
    if (this.stopped) return;
    const wait = this.backoff;
    this.backoff = Math.min(this.backoff * 2, MAX_BACKOFF_MS);
    this.handlers.onStatus(state, `${message} · retrying in ${(wait / 1000).toFixed(1)} s`);
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.connect(), wait);
  }
}
