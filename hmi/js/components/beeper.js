// The alarm horn: a short WebAudio oscillator pattern, no audio files. The
// operator can mute it; the choice is kept in this browser.

const KEY = 'gridscada.alarmMuted';

export class Beeper {
  constructor() {
    this.ctx = null;
    this.muted = localStorage.getItem(KEY) === '1';
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

  setMuted(m) {
    this.muted = m;
    localStorage.setItem(KEY, m ? '1' : '0');
  }

  /** Three short tones; louder pitch for higher priority. */
  beep(priority = 500) {
    if (this.muted) return;
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
