// The standing query (`/v1/stream`, DESIGN.md "WebSocket messages"): the viewer sends its view
// at most every MIN_INTERVAL_MS while it moves, and hands each reset and delta to the world.
// The time from sending a view to the first message that names it is the camera-to-delta
// latency. A dropped connection is reopened; the server starts it with a reset.

export const MIN_INTERVAL_MS = 100;

export class Stream {
  /**
   * @param {object} handlers `onReset(message)`, `onDelta(message)`, `onError(text)`,
   *   `onState(text)`
   */
  constructor(handlers) {
    this.handlers = handlers;
    this.socket = null;
    this.viewId = 0;
    this.sentAt = new Map();
    this.lastSent = 0;
    this.lastView = null;
    this.queued = null;
    this.timer = null;
    this.latencyMs = null;
    this.messages = 0;
    this.retryMs = 500;
    this.connect();
  }

  connect() {
    const scheme = location.protocol === 'https:' ? 'wss' : 'ws';
    const socket = new WebSocket(`${scheme}://${location.host}/v1/stream`);
    this.socket = socket;
    socket.onopen = () => {
      this.retryMs = 500;
      this.handlers.onState?.('connected');
      if (this.lastView) this.transmit(this.lastView);
    };
    socket.onmessage = (event) => this.receive(event.data);
    socket.onclose = (event) => {
      if (this.socket !== socket) return;
      this.handlers.onState?.(`disconnected (${event.code}${event.reason ? ` ${event.reason}` : ''}); retrying`);
      setTimeout(() => this.connect(), this.retryMs);
      this.retryMs = Math.min(this.retryMs * 2, 8000);
    };
  }

  /** Asks for the cut at `view` (eye, min_solid_angle, pixel_solid_angle, budgets). */
  setView(view) {
    const same = this.lastView && JSON.stringify(view) === JSON.stringify(this.lastView);
    if (same && !this.queued) return;
    this.queued = view;
    const wait = this.lastSent + MIN_INTERVAL_MS - performance.now();
    if (wait <= 0) {
      this.flush();
    } else if (!this.timer) {
      this.timer = setTimeout(() => this.flush(), wait);
    }
  }

  flush() {
    this.timer = null;
    if (!this.queued) return;
    const view = this.queued;
    this.queued = null;
    this.lastView = view;
    this.transmit(view);
  }

  transmit(view) {
    if (!this.socket || this.socket.readyState !== WebSocket.OPEN) return;
    const id = ++this.viewId;
    this.sentAt.set(id, performance.now());
    this.lastSent = performance.now();
    this.socket.send(JSON.stringify({ type: 'view', id, ...view }));
  }

  receive(text) {
    let message;
    try {
      message = JSON.parse(text);
    } catch {
      this.handlers.onError?.('the server sent a message that is not JSON');
      return;
    }
    this.messages++;
    if (message.type === 'error') {
      this.handlers.onError?.(message.error?.message || 'stream error');
      return;
    }
    const sent = this.sentAt.get(message.view);
    if (sent !== undefined) {
      this.latencyMs = performance.now() - sent;
      // Views up to this one have been answered.
      for (const id of this.sentAt.keys()) if (id <= message.view) this.sentAt.delete(id);
    }
    if (message.type === 'reset') this.handlers.onReset(message);
    else if (message.type === 'delta') this.handlers.onDelta(message);
    if (message.seq !== undefined && this.socket.readyState === WebSocket.OPEN) {
      this.socket.send(JSON.stringify({ type: 'ack', seq: message.seq }));
    }
  }
}
