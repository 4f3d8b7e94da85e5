// The alarm horn: a WebAudio oscillator pattern, no audio files. It sounds
// again and again while an active alarm is unacknowledged, until the operator
// silences it (those alarms; a new one sounds again) or acknowledges them.
// Mute is for a while only (MUTE_MS) and belongs to the logged-in session:
// it is kept in sessionStorage with the user's name, and a log out ends it.

const KEY = 'gridscada.alarmMuted';
const REPEAT_MS = 2000;
export const MUTE_MS = 15 * 60_000;

export class Beeper {
  constructor() {
    this.ctx = null;
    this.user = null;
    this.pending = new Map(); // unacknowledged active alarm id -> priority
    this.silenced = new Set(); // ids silenced by the operator
    this.timer = null;
    this.listeners = new Set();
    this.beeps = 0;
    // Browsers allow audio only after a user gesture: prepare the context on the first one.
    const unlock = () => {
      this.context();
      window.removeEventListener('pointerdown', unlock);
      window.removeEventListener('keydown', unlock);
    };
    window.addEventListener('pointerdown', unlock);
    window.addEventListener('keydown', unlock);
  }

  context() {
    if (!this.ctx) {
      const AC = window.AudioContext || window.webkitAudioContext;
      if (!AC) return null;
      try { this.ctx = new AC(); } catch { return null; }
    }
    if (this.ctx.state === 'suspended') this.ctx.resume().catch(() => {});
    return this.ctx;
  }

  /** The session's user: a mute set by another user (or before a log out) does not apply. */
  setUser(user) {
    if (user !== this.user) { this.silenced.clear(); }
    this.user = user;
    if (!user) { try { sessionStorage.removeItem(KEY); } catch { /* private mode */ } }
    this.update();
  }

  /** Until when the horn is muted (ms), or 0. */
  get mutedUntil() {
    try {
      const m = JSON.parse(sessionStorage.getItem(KEY) || 'null');
      return m && m.user === this.user && m.until > Date.now() ? m.until : 0;
    } catch { return 0; }
  }

  get muted() { return this.mutedUntil > 0; }

  setMuted(on) {
    try {
      if (on) sessionStorage.setItem(KEY, JSON.stringify({ user: this.user, until: Date.now() + MUTE_MS }));
      else sessionStorage.removeItem(KEY);
    } catch { /* private mode: not kept */ }
    this.update();
  }

  /** Silences the alarms sounding now; a new alarm sounds again. */
  silence() {
    for (const id of this.pending.keys()) this.silenced.add(id);
    this.update();
  }

  /** The unacknowledged active alarms ([{id, priority}]): the horn sounds while any is not silenced. */
  setAlarms(list) {
    this.pending = new Map(list.map((a) => [a.id, a.priority]));
    for (const id of [...this.silenced]) if (!this.pending.has(id)) this.silenced.delete(id);
    this.update();
  }

  /** 'sounding', 'silenced' (alarms waiting, horn quiet), 'muted' or 'quiet'. */
  get state() {
    const loud = [...this.pending.keys()].filter((id) => !this.silenced.has(id));
    if (this.muted && this.pending.size) return 'muted';
    if (loud.length) return 'sounding';
    return this.pending.size ? 'silenced' : 'quiet';
  }

  onChange(f) { this.listeners.add(f); return () => this.listeners.delete(f); }

  update() {
    const st = this.state;
    if (st === 'sounding' && !this.timer) {
      this.sound();
      this.timer = setInterval(() => {
        if (this.state === 'sounding') this.sound();
        else { clearInterval(this.timer); this.timer = null; }
      }, REPEAT_MS);
    } else if (st !== 'sounding' && this.timer) {
      clearInterval(this.timer);
      this.timer = null;
    }
    for (const f of this.listeners) f(st);
  }

  sound() {
    const loud = [...this.pending].filter(([id]) => !this.silenced.has(id)).map(([, p]) => p);
    this.beeps += 1;
    this.beep(Math.max(0, ...loud));
    for (const f of this.listeners) f(this.state);
  }

  /** Three short tones; higher pitch for higher priority. */
  beep(priority = 500) {
    const ctx = this.context();
    if (!ctx || ctx.state !== 'running') return;
    const freq = priority >= 700 ? 1046 : 880;
    const t0 = ctx.currentTime + 0.02;
    for (let i = 0; i < 3; i++) {
      const osc = ctx.createOscillator();
      const gain = ctx.createGain();
      osc.type = 'square';
      osc.frequency.value = freq;
      const t = t0 + i * 0.25;
      gain.gain.setValueAtTime(0.0001, t);
      gain.gain.exponentialRampToValueAtTime(0.08, t + 0.01);
      gain.gain.exponentialRampToValueAtTime(0.0001, t + 0.15);
      osc.connect(gain).connect(ctx.destination);
      osc.start(t);
      osc.stop(t + 0.16);
    }
  }
}

export const beeper = new Beeper();
