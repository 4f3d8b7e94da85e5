// A trend chart on <canvas>. It draws what the server downsampled (one
// bucket per pixel or so, with min/max band and average line), so a week of
// 1 s data stays smooth. Each unit has its own Y axis (kW, V, A, Hz, % ...),
// and every pen is drawn on the axis of its units. A cursor, moved by mouse,
// touch or arrow keys, reads the values of every pen at one time. The view
// pans (drag, or the Left/Right keys with Shift) and zooms (wheel, + and -);
// the chart only proposes the new window through `onView`: the screen
// decides (and never lets it reach into the future).

import { fmtDate, fmtNumber, fmtTime, pad } from '../format.js';

// Pens: blues, greens, greys and browns, readable on the light and the dark
// plot; none red, orange, yellow or purple, the alarm colours (ISA-101).
export const PEN_COLORS = ['#1d5fa8', '#00838f', '#2e7d32', '#78909c', '#8d6e63', '#26a69a', '#0288d1', '#546e7a'];

/** Room of one Y axis (its tick labels and unit), and the plot's other margins. */
const AXIS_W = 58;
const M = { top: 22, bottom: 28, pad: 10 };
/** A press that moves less than this is a click (the cursor), not a drag (a pan). */
const DRAG_PX = 4;

/** The chart's colours, from the page's theme (docs/HMI_STYLE.md). */
function themeColors(el) {
  const cs = getComputedStyle(el);
  const v = (name, fallback) => (cs.getPropertyValue(name) || '').trim() || fallback;
  return { grid: v('--line-soft', '#d5d9de'), text: v('--muted', '#4f5762'), frame: v('--control-border', '#7d8794'), ink: v('--ink', '#1b1f24'), plot: v('--field', '#ffffff') };
}

/** The Y axes of a set of series: one per unit, in the order units first appear. */
export function axesOf(series) {
  const axes = [];
  for (const s of series) {
    const unit = s.units || '';
    let a = axes.find((x) => x.unit === unit);
    if (!a) { a = { unit, pens: [] }; axes.push(a); }
    a.pens.push(s.tag);
  }
  // Alternate sides: the first axis on the left, the second on the right, and so on outwards.
  axes.forEach((a, i) => { a.side = i % 2 === 0 ? 'left' : 'right'; a.slot = Math.floor(i / 2); });
  return axes;
}

export class TrendChart {
  /**
   * `onCursor({t, values:[{tag, bucket}]})` is called when the cursor moves;
   * `onView({from, to})` when the user pans or zooms (omit it for a fixed chart).
   */
  constructor(canvas, { onCursor, onView } = {}) {
    this.canvas = canvas;
    this.onCursor = onCursor || (() => {});
    this.onView = onView || null;
    this.series = [];
    this.axes = [];
    this.from = Date.now() - 3_600_000;
    this.to = Date.now();
    this.yFixed = new Map(); // unit -> {min, max}; the others automatic
    this.cursorT = null;
    this.anchorEnd = false; // set while live: a zoom keeps the window ending now
    canvas.tabIndex = 0;
    canvas.setAttribute('role', 'img');
    canvas.setAttribute('aria-label', this.onView
      ? 'Trend chart. Arrow keys move the cursor; Shift with the arrow keys pans, plus and minus zoom.'
      : 'Trend chart. Use the left and right arrow keys to move the cursor.');
    this.ro = new ResizeObserver(() => this.draw());
    this.ro.observe(canvas);
    this.onTheme = () => this.draw();
    window.addEventListener('gridscada-theme', this.onTheme);
    const timeAt = (clientX) => {
      const r = canvas.getBoundingClientRect();
      const { left, pw } = this.plotBox(r.width);
      const f = Math.min(1, Math.max(0, (clientX - r.left - left) / pw));
      return this.from + f * (this.to - this.from);
    };
    let press = null;
    canvas.addEventListener('pointerdown', (e) => {
      press = { x: e.clientX, from: this.from, to: this.to, dragging: false, id: e.pointerId };
      this.setCursor(timeAt(e.clientX));
    });
    canvas.addEventListener('pointermove', (e) => {
      if (press && this.onView && (press.dragging || Math.abs(e.clientX - press.x) > DRAG_PX)) {
        if (!press.dragging) { press.dragging = true; canvas.setPointerCapture(press.id); canvas.classList.add('panning'); }
        const r = canvas.getBoundingClientRect();
        const { pw } = this.plotBox(r.width);
        const dt = -((e.clientX - press.x) / pw) * (press.to - press.from);
        this.showView(press.from + dt, press.to + dt);
        return;
      }
      this.setCursor(timeAt(e.clientX));
    });
    const release = () => {
      if (press && press.dragging) {
        canvas.classList.remove('panning');
        if (canvas.hasPointerCapture(press.id)) canvas.releasePointerCapture(press.id);
        this.propose(this.from, this.to, 'pan');
      }
      press = null;
    };
    canvas.addEventListener('pointerup', release);
    canvas.addEventListener('pointercancel', release);
    canvas.addEventListener('wheel', (e) => {
      if (!this.onView) return;
      e.preventDefault();
      this.zoom(e.deltaY > 0 ? 1.25 : 0.8, timeAt(e.clientX));
    }, { passive: false });
    canvas.addEventListener('keydown', (e) => {
      const span = this.to - this.from;
      if (this.onView && e.shiftKey && (e.key === 'ArrowLeft' || e.key === 'ArrowRight')) {
        e.preventDefault();
        this.pan(e.key === 'ArrowLeft' ? -0.25 : 0.25);
        return;
      }
      if (this.onView && (e.key === '+' || e.key === '=' || e.key === '-')) {
        e.preventDefault();
        this.zoom(e.key === '-' ? 1.25 : 0.8, this.cursorT ?? this.from + span / 2);
        return;
      }
      const step = this.bucketMs() || span / 100;
      const t = this.cursorT ?? this.from + span / 2;
      const k = { ArrowLeft: -1, ArrowRight: 1, PageUp: -10, PageDown: 10 }[e.key];
      if (k) { e.preventDefault(); this.setCursor(Math.min(this.to, Math.max(this.from, t + k * step))); }
      if (e.key === 'Home') { e.preventDefault(); this.setCursor(this.from); }
      if (e.key === 'End') { e.preventDefault(); this.setCursor(this.to); }
    });
  }

  /** Pans by a fraction of the window (negative: back in time). */
  pan(fraction) {
    const span = this.to - this.from;
    this.propose(this.from + fraction * span, this.to + fraction * span, 'pan');
  }

  /** Zooms by `factor` (above 1: out) around time `center`; a live window (anchorEnd) keeps its end. */
  zoom(factor, center = (this.from + this.to) / 2) {
    if (this.anchorEnd) center = this.to;
    const span = Math.max(10_000, (this.to - this.from) * factor);
    const f = (center - this.from) / Math.max(1, this.to - this.from);
    this.propose(center - f * span, center - f * span + span, 'zoom');
  }

  /** Shows a window at once (with the data there is), then asks the screen for it ('pan' or 'zoom'). */
  propose(from, to, kind) {
    // The window asked for is kept apart: a live update may redraw the old one meanwhile.
    const view = { ...this.showView(from, to), kind };
    clearTimeout(this.viewTimer);
    // A burst of wheel steps asks once, for the last window.
    this.viewTimer = setTimeout(() => { if (this.onView) this.onView(view); }, 150);
  }

  /** Draws the window [from, to]; it never reaches past now (the screen clamps again). */
  showView(from, to) {
    const span = to - from;
    const now = Date.now();
    if (to > now) { to = now; from = now - span; }
    this.from = from;
    this.to = to;
    this.draw();
    return { from, to };
  }

  bucketMs() {
    const s = this.series.find((x) => x.buckets.length > 1);
    return s ? (s.buckets[1].start - s.buckets[0].start) : 0;
  }

  /** series: [{tag, color, units, buckets:[{start, end, min, max, avg, last, count}]}]. */
  setData(series, from, to) {
    this.series = series;
    this.axes = axesOf(series);
    this.from = from;
    this.to = to;
    if (this.cursorT !== null && (this.cursorT < from || this.cursorT > to)) this.cursorT = null;
    this.draw();
    if (this.cursorT !== null) this.setCursor(this.cursorT);
  }

  /** Fixes the range of the axis of `unit` ({min, max}), or sets it automatic (null). */
  setY(unit, fixed) {
    if (fixed) this.yFixed.set(unit, fixed); else this.yFixed.delete(unit);
    this.draw();
  }

  setCursor(t) {
    this.cursorT = t;
    this.draw();
    this.onCursor({ t, values: this.series.map((s) => ({ tag: s.tag, color: s.color, units: s.units, bucket: bucketAt(s.buckets, t) })) });
  }

  /** The range of the axis of `unit`: fixed, or from its pens' data in view. */
  yRange(unit = (this.axes[0] || {}).unit || '') {
    if (this.yFixed.has(unit)) return this.yFixed.get(unit);
    let min = Infinity;
    let max = -Infinity;
    for (const s of this.series) {
      if ((s.units || '') !== unit) continue;
      for (const b of s.buckets) {
        if (b.count === 0 || b.min === null || b.max === null) continue;
        if (b.end < this.from || b.start > this.to) continue;
        if (b.min < min) min = b.min;
        if (b.max > max) max = b.max;
      }
    }
    if (!Number.isFinite(min)) return { min: 0, max: 1 };
    if (min === max) { min -= 1; max += 1; }
    const m = (max - min) * 0.06;
    return { min: min - m, max: max + m };
  }

  /** The plot's box inside a canvas `w` wide: room for the axes on each side. */
  plotBox(w) {
    const n = this.axes.length || 1;
    const left = Math.ceil(n / 2) * AXIS_W;
    const right = Math.max(M.pad + 4, Math.floor(n / 2) * AXIS_W);
    return { left, right, pw: Math.max(10, w - left - right) };
  }

  /** The axes as drawn: [{unit, side, pens, min, max}] (the screen lists them). */
  axesInfo() {
    return this.axes.map((a) => ({ ...a, ...this.yRange(a.unit) }));
  }

  draw() {
    const c = this.canvas;
    const dpr = window.devicePixelRatio || 1;
    const w = c.clientWidth;
    const hgt = c.clientHeight;
    if (!w || !hgt) return;
    if (c.width !== Math.round(w * dpr) || c.height !== Math.round(hgt * dpr)) {
      c.width = Math.round(w * dpr);
      c.height = Math.round(hgt * dpr);
    }
    const col = themeColors(c);
    const g = c.getContext('2d');
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, w, hgt);
    const { left, pw } = this.plotBox(w);
    const ph = hgt - M.top - M.bottom;
    const span = Math.max(1, this.to - this.from);
    const X = (t) => left + ((t - this.from) / span) * pw;
    const axes = this.axes.length ? this.axes : [{ unit: '', side: 'left', slot: 0, pens: [] }];
    const ranges = new Map(axes.map((a) => [a.unit, this.yRange(a.unit)]));
    const Yof = (unit) => { const { min, max } = ranges.get(unit); return (v) => M.top + (1 - (v - min) / (max - min)) * ph; };
    const nTicks = Math.max(2, Math.floor(ph / 40));

    g.fillStyle = col.plot;
    g.fillRect(left, M.top, pw, ph);
    g.font = '11px system-ui, sans-serif';
    g.lineWidth = 1;
    // Each axis: its ticks and labels on its side; the first axis draws the grid.
    axes.forEach((a, i) => {
      const { min, max } = ranges.get(a.unit);
      const Y = Yof(a.unit);
      const x0 = a.side === 'left' ? left - a.slot * AXIS_W : left + pw + a.slot * AXIS_W;
      const dir = a.side === 'left' ? -1 : 1;
      g.strokeStyle = col.frame;
      g.beginPath(); g.moveTo(x0 + 0.5, M.top); g.lineTo(x0 + 0.5, M.top + ph); g.stroke();
      g.fillStyle = col.text;
      g.textAlign = a.side === 'left' ? 'right' : 'left';
      g.textBaseline = 'middle';
      for (const v of niceTicks(min, max, nTicks)) {
        const y = Math.round(Y(v)) + 0.5;
        if (i === 0) { g.strokeStyle = col.grid; g.beginPath(); g.moveTo(left, y); g.lineTo(left + pw, y); g.stroke(); }
        g.strokeStyle = col.frame;
        g.beginPath(); g.moveTo(x0, y); g.lineTo(x0 + dir * 4, y); g.stroke();
        g.fillText(fmtNumber(v, tickDigits(min, max, nTicks)), x0 + dir * 6, y);
      }
      // The unit on top of its axis, with the colour of its first pen as a mark.
      const pen = this.series.find((s) => (s.units || '') === a.unit);
      g.textBaseline = 'bottom';
      g.font = 'bold 11px system-ui, sans-serif';
      const label = a.unit || '(no unit)';
      g.fillStyle = col.ink;
      g.fillText(label, x0 + dir * 6, M.top - 6);
      if (pen) { g.fillStyle = pen.color; g.fillRect(a.side === 'left' ? x0 - 4 : x0 + 1, M.top - 16, 3, 12); }
      g.font = '11px system-ui, sans-serif';
    });
    g.fillStyle = col.text;
    g.textAlign = 'center';
    g.textBaseline = 'top';
    // Time ticks on round intervals of the local clock (10:00, 10:05, 10:10), labels kept inside the plot.
    const ticks = timeTicks(this.from, this.from + span, Math.max(2, Math.floor(pw / 110)));
    for (const t of ticks.times) {
      const x = Math.round(X(t)) + 0.5;
      g.strokeStyle = col.grid;
      g.beginPath(); g.moveTo(x, M.top); g.lineTo(x, M.top + ph); g.stroke();
      const label = timeLabel(t, ticks.step, span);
      const half = g.measureText(label).width / 2;
      g.textAlign = 'center';
      g.fillText(label, Math.min(Math.max(x, left + half), left + pw - half), M.top + ph + 6);
    }
    g.strokeStyle = col.frame;
    g.strokeRect(left + 0.5, M.top + 0.5, pw, ph);

    // Pens: min/max band, then the average line, on the axis of their units; gaps where a bucket is empty.
    g.save();
    g.beginPath(); g.rect(left, M.top, pw, ph); g.clip();
    for (const s of this.series) {
      const Y = Yof(s.units || '');
      g.fillStyle = s.color + '33';
      for (const b of s.buckets) {
        if (!b.count || b.min === null) continue;
        const x0 = X(b.start);
        const x1 = Math.max(x0 + 1, X(b.end));
        const y0 = Y(b.max);
        g.fillRect(x0, y0, x1 - x0, Math.max(1, Y(b.min) - y0));
      }
      // The store records by exception: a value holds until the next sample,
      // so the line is drawn as steps, up to the end of the range or now.
      g.strokeStyle = s.color;
      g.lineWidth = 1.6;
      g.beginPath();
      let prevY = null;
      for (const b of s.buckets) {
        if (!b.count || b.avg === null) continue;
        const x = X(b.start);
        if (prevY === null) g.moveTo(x, Y(b.avg));
        else { g.lineTo(x, prevY); g.lineTo(x, Y(b.avg)); }
        prevY = Y(b.last ?? b.avg);
        g.lineTo(Math.max(x, X(b.end)), prevY);
      }
      if (prevY !== null) g.lineTo(X(Math.min(this.to, Date.now())), prevY);
      g.stroke();
    }
    g.restore();

    // Cursor.
    if (this.cursorT !== null && this.cursorT >= this.from && this.cursorT <= this.to) {
      const x = Math.round(X(this.cursorT)) + 0.5;
      g.strokeStyle = col.ink;
      g.setLineDash([4, 3]);
      g.beginPath(); g.moveTo(x, M.top); g.lineTo(x, M.top + ph); g.stroke();
      g.setLineDash([]);
    }
    if (this.series.every((s) => s.buckets.every((b) => !b.count || b.end < this.from || b.start > this.to))) {
      g.fillStyle = col.text;
      g.textAlign = 'center';
      g.textBaseline = 'middle';
      g.font = 'italic 13px system-ui, sans-serif';
      g.fillText('No data in this range', left + pw / 2, M.top + ph / 2);
    }
  }

  dispose() {
    this.ro.disconnect();
    clearTimeout(this.viewTimer);
    window.removeEventListener('gridscada-theme', this.onTheme);
  }
}

/**
 * The bucket that gives the value at time t: the last one starting at or
 * before t (values hold until the next sample), or null before the first.
 */
export function bucketAt(buckets, t) {
  let lo = 0;
  let hi = buckets.length - 1;
  let found = null;
  while (lo <= hi) {
    const mid = (lo + hi) >> 1;
    if (buckets[mid].start <= t) { found = mid; lo = mid + 1; } else hi = mid - 1;
  }
  for (let i = found; i !== null && i >= 0; i--) {
    if (buckets[i].count) return buckets[i];
  }
  return null;
}

function tickStep(min, max, n) {
  const raw = (max - min) / n;
  const mag = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 2.5, 5, 10].map((k) => k * mag).find((s) => s >= raw) || raw;
}

function tickDigits(min, max, n) {
  const step = tickStep(min, max, n);
  return Math.max(0, Math.min(6, -Math.floor(Math.log10(step)) + (Math.abs(step / 10 ** Math.floor(Math.log10(step)) - 2.5) < 1e-9 ? 1 : 0)));
}

function niceTicks(min, max, n) {
  const step = tickStep(min, max, n);
  const out = [];
  for (let v = Math.ceil(min / step) * step; v <= max + step * 1e-9; v += step) out.push(Math.abs(v) < step * 1e-9 ? 0 : v);
  return out;
}

/** The tick steps an axis may take: round seconds, minutes, hours and days. */
const TIME_STEPS = [1, 2, 5, 10, 15, 30].map((s) => s * 1000)
  .concat([1, 2, 5, 10, 15, 30].map((m) => m * 60_000), [1, 2, 3, 6, 12].map((h) => h * 3_600_000), [1, 2, 7, 14].map((d) => d * 86_400_000));

/**
 * Ticks of a time axis from `from` to `to` (ms), at most `max` of them: the
 * smallest round step that fits, every tick a whole multiple of it on the
 * local clock. {step, times}.
 */
export function timeTicks(from, to, max) {
  const span = Math.max(1, to - from);
  const step = TIME_STEPS.find((s) => span / s <= max) || TIME_STEPS[TIME_STEPS.length - 1];
  // Local clock time = UTC time - offset: align the ticks on the local clock.
  const offset = new Date(from).getTimezoneOffset() * 60_000;
  const times = [];
  for (let t = Math.ceil((from - offset) / step) * step + offset; t <= to; t += step) times.push(t);
  return { step, times };
}

function timeLabel(t, step, span) {
  const d = new Date(t);
  const hm = `${pad(d.getHours())}:${pad(d.getMinutes())}`;
  if (step < 60_000) return `${hm}:${pad(d.getSeconds())}`;
  if (span <= 36 * 3_600_000) return hm;
  // Days apart: the day and month in the plant's order (`[hmi] date_format`).
  return `${fmtDate(d, { year: false })} ${hm}`;
}

export { fmtTime };
