// The live connection: one WebSocket to /api/live for the whole app. Screens
// register interests (tags, prefixes, alarms); the union is sent as the
// subscription, and sent again after every reconnect. Values are kept in a
// cache so a screen mounted later sees them at once.

import { apiUrl } from './api.js';
import { noteActivity } from './session.js';

const RETRY_MIN_MS = 500;
const RETRY_MAX_MS = 10_000;
/** The server sends a heartbeat every second: silence this long means it is not answering. */
const SILENCE_MS = 2200;
/** A connection not open by then is given up and tried again. */
const CONNECT_TIMEOUT_MS = 5000;
/** How often, at most, a screen on view tells the server it is watched (keeps a wall display logged in); more often for a short idle timeout (`live.visibleMs`). */
const VISIBLE_MS = 60_000;

export class Live {
  constructor() {
    this.values = new Map(); // name -> {value, quality, timestamp}
    this.alarms = [];
    this.alarmVersion = null;
    this.connected = false;
    this.everConnected = false;
    this.interests = new Set();
    this.tagListeners = new Set();
    this.alarmListeners = new Set();
    this.statusListeners = new Set();
    this.ws = null;
    this.retry = RETRY_MIN_MS;
    this.timer = null;
    this.stopped = true;
    this.onSessionEnded = () => {};
    this.onConnectFailed = () => {};
    this.lastMessage = 0;
    this.silent = false;
    // A frozen server keeps its socket open and says nothing: the heartbeat's
    // absence is what tells. A screen on view also says it is watched.
    this.watchdog = setInterval(() => this.check(), 250);
  }

  check() {
    if (!this.ws || this.stopped) return;
    const now = Date.now();
    if (this.connected && now - this.lastMessage > SILENCE_MS) {
      this.silent = true;
      const ws = this.ws;
      ws.onclose = null;
      try { ws.close(4000, 'no heartbeat'); } catch { /* already closing */ }
      this.ws = null;
      this.setConnected(false);
      this.scheduleReconnect();
      return;
    }
    // Only on an open socket: a send on a closing one is logged as an error.
    if (this.connected && this.ws.readyState === WebSocket.OPEN && document.visibilityState === 'visible'
      && now - (this.lastVisible || 0) > (this.visibleMs || VISIBLE_MS)) {
      this.lastVisible = now;
      try {
        this.ws.send(JSON.stringify({ visible: true }));
        noteActivity();
      } catch { /* reconnecting */ }
    }
  }

  start() {
    this.stopped = false;
    this.connect();
  }

  stop() {
    this.stopped = true;
    clearTimeout(this.timer);
    if (this.ws) { this.ws.onclose = null; this.ws.close(1000); }
    this.ws = null;
    this.setConnected(false);
    this.values.clear();
    this.alarms = [];
    this.alarmVersion = null;
  }

  connect() {
    if (this.stopped) return;
    // Under the HMI's base (a reverse proxy's sub-path), ws: or wss: as the page.
    const live = new URL(apiUrl('/api/live'));
    live.protocol = live.protocol === 'https:' ? 'wss:' : 'ws:';
    const url = live.href;
    let ws;
    try { ws = new WebSocket(url); } catch { this.scheduleReconnect(); return; }
    this.ws = ws;
    let opened = false;
    const giveUp = setTimeout(() => { if (!opened && this.ws === ws) { ws.close(); } }, CONNECT_TIMEOUT_MS);
    ws.onopen = () => {
      opened = true;
      clearTimeout(giveUp);
      this.retry = RETRY_MIN_MS;
      this.lastMessage = Date.now();
      this.silent = false;
      this.setConnected(true);
      this.sendSubscription();
    };
    ws.onmessage = (ev) => { this.lastMessage = Date.now(); this.handle(ev.data); };
    ws.onclose = (ev) => {
      clearTimeout(giveUp);
      this.ws = null;
      this.setConnected(false);
      if (ev.code === 4001) { this.onSessionEnded(); return; }
      // A refused upgrade (e.g. the session is gone after a server restart) looks like a failed connection.
      if (!opened) this.onConnectFailed();
      this.scheduleReconnect();
    };
    ws.onerror = () => {}; // onclose follows and reconnects
  }

  scheduleReconnect() {
    if (this.stopped) return;
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.connect(), this.retry);
    this.retry = Math.min(this.retry * 2, RETRY_MAX_MS);
  }

  setConnected(c) {
    if (this.connected === c) return;
    this.connected = c;
    if (c) this.everConnected = true;
    for (const f of this.statusListeners) f(c);
  }

  handle(text) {
    let msg;
    try { msg = JSON.parse(text); } catch { return; }
    if (msg.type === 'tags' && Array.isArray(msg.values)) {
      if (msg.snapshot) this.values.clear();
      const changed = [];
      for (const v of msg.values) {
        if (!v || typeof v.name !== 'string') continue;
        this.values.set(v.name, { value: v.value, quality: v.quality, timestamp: v.timestamp });
        changed.push(v.name);
      }
      for (const f of this.tagListeners) f(changed, !!msg.snapshot);
    } else if (msg.type === 'alarms' && Array.isArray(msg.alarms)) {
      this.alarms = msg.alarms;
      this.alarmVersion = msg.version;
      for (const f of this.alarmListeners) f(this.alarms);
    } else if (msg.type === 'alarm_changes' && Array.isArray(msg.changed) && Array.isArray(msg.removed)) {
      // What changed since the list we have; a list we do not have is asked for whole.
      if (msg.since !== this.alarmVersion) { this.alarmVersion = null; this.sendSubscription(); return; }
      const byId = new Map(this.alarms.map((a) => [a.id, a]));
      for (const id of msg.removed) byId.delete(id);
      for (const a of msg.changed) byId.set(a.id, a);
      // The server's order: newest change first, then higher priority.
      this.alarms = [...byId.values()].sort((a, b) => (b.last_change - a.last_change) || (b.priority - a.priority) || (a.id - b.id));
      this.alarmVersion = msg.version;
      for (const f of this.alarmListeners) f(this.alarms);
    } else if (msg.type === 'error') {
      console.warn('live:', msg.detail);
    }
  }

  /** The union of all interests, sent to the server. */
  sendSubscription() {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) return;
    const tags = new Set();
    const prefixes = new Set();
    let alarms = false;
    for (const i of this.interests) {
      (i.tags || []).forEach((t) => tags.add(t));
      (i.prefixes || []).forEach((p) => prefixes.add(p));
      alarms = alarms || !!i.alarms;
    }
    // The alarm list comes whole once, then as its changes (a flood of standing alarms is not resent whole);
    // the version held lets a screen change go on with the changes (the server sends the list whole if it is not the one it sent).
    const held = alarms && this.alarmVersion !== null ? this.alarmVersion : undefined;
    this.ws.send(JSON.stringify({ subscribe: { tags: [...tags], prefixes: [...prefixes], alarms, alarm_changes: alarms, alarm_version: held } }));
  }

  /**
   * Registers an interest {tags, prefixes, alarms}; returns a function that
   * removes it. The subscription is re-sent on every change.
   */
  want(interest) {
    this.interests.add(interest);
    this.sendSubscription();
    return () => { this.interests.delete(interest); this.sendSubscription(); };
  }

  get(name) { return this.values.get(name); }

  onTags(f) { this.tagListeners.add(f); return () => this.tagListeners.delete(f); }
  onAlarms(f) { this.alarmListeners.add(f); return () => this.alarmListeners.delete(f); }
  onStatus(f) { this.statusListeners.add(f); return () => this.statusListeners.delete(f); }
}

export const live = new Live();
