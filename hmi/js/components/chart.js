// A trend chart on <canvas>. It draws what the server downsampled (one
// bucket per pixel or so, with min/max band and average line), so a week of
// 1 s data stays smooth. A cursor, moved by mouse, touch or arrow keys,
// reads the values of every pen at one time.

import { fmtNumber, fmtTime, pad } from '../format.js';

export const PEN_COLORS = ['#1d5fa8', '#c62828', '#1e8a3c', '#b26a00', '#6a3fb5', '#00838f', '#ad1457', '#4e5b6a'];

const M = { left: 62, right: 14, top: 12, bottom: 28 };

export class TrendChart {
  /** `onCursor({t, values:[{tag, bucket}]})` is called when the cursor moves. */
  constructor(canvas, { onCursor } = {}) {
    this.canvas = canvas;
    this.onCursor = onCursor || (() => {});
    this.series = [];
    this.from = Date.now() - 3_600_000;
    this.to = Date.now();
    this.yFixed = null; // {min, max} or null for automatic
    this.cursorT = null;
    canvas.tabIndex = 0;
    canvas.setAttribute('role', 'img');
    canvas.setAttribute('aria-label', 'Trend chart. Use the left and right arrow keys to move the cursor.');
    this.ro = new ResizeObserver(() => this.draw());
    this.ro.observe(canvas);
    const moveTo = (clientX) => {
      const r = canvas.getBoundingClientRect();
      const x = clientX - r.left;
      const w = r.width - M.left - M.right;
      const f = Math.min(1, Math.max(0, (x - M.left) / w));
      this.setCursor(this.from + f * (this.to - this.from));
    };
    canvas.addEventListener('pointermove', (e) => moveTo(e.clientX));
    canvas.addEventListener('pointerdown', (e) => moveTo(e.clientX));
    canvas.addEventListener('keydown', (e) => {
      const span = this.to - this.from;
      const step = this.bucketMs() || span / 100;
      const t = this.cursorT ?? this.from + span / 2;
      const k = { ArrowLeft: -1, ArrowRight: 1, PageUp: -10, PageDown: 10 }[e.key];
      if (k) { e.preventDefault(); this.setCursor(Math.min(this.to, Math.max(this.from, t + k * step))); }
      if (e.key === 'Home') { e.preventDefault(); this.setCursor(this.from); }
      if (e.key === 'End') { e.preventDefault(); this.setCursor(this.to); }
    });
  }

  bucketMs() {
    const s = this.series.find((x) => x.buckets.length > 1);
    return s ? (s.buckets[1].start - s.buckets[0].start) : 0;
  }

  /** series: [{tag, color, units, buckets:[{start, end, min, max, avg, last, count}]}]. */
  setData(series, from, to) {
    this.series = series;
    this.from = from;
    this.to = to;
    if (this.cursorT !== null && (this.cursorT < from || this.cursorT > to)) this.cursorT = null;
    this.draw();
    if (this.cursorT !== null) this.setCursor(this.cursorT);
  }

  setY(fixed) { this.yFixed = fixed; this.draw(); }

  setCursor(t) {
    this.cursorT = t;
    this.draw();
    this.onCursor({ t, values: this.series.map((s) => ({ tag: s.tag, color: s.color, units: s.units, bucket: bucketAt(s.buckets, t) })) });
  }

  yRange() {
    if (this.yFixed) return this.yFixed;
    let min = Infinity;
    let max = -Infinity;
    for (const s of this.series) {
      for (const b of s.buckets) {
        if (b.count === 0 || b.min === null || b.max === null) continue;
        if (b.min < min) min = b.min;
        if (b.max > max) max = b.max;
      }
    }
    if (!Number.isFinite(min)) return { min: 0, max: 1 };
    if (min === max) { min -= 1; max += 1; }
    const m = (max - min) * 0.06;
    return { min: min - m, max: max + m };
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
    const g = c.getContext('2d');
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, w, hgt);
    const pw = w - M.left - M.right;
    const ph = hgt - M.top - M.bottom;
    const { min, max } = this.yRange();
    const span = Math.max(1, this.to - this.from);
    const X = (t) => M.left + ((t - this.from) / span) * pw;
    const Y = (v) => M.top + (1 - (v - min) / (max - min)) * ph;

    // Grid and axes.
    g.font = '11px system-ui, sans-serif';
    g.strokeStyle = '#e1e6ec';
    g.fillStyle = '#5b6675';
    g.lineWidth = 1;
    g.textAlign = 'right';
    g.textBaseline = 'middle';
    for (const v of niceTicks(min, max, Math.max(2, Math.floor(ph / 40)))) {
      const y = Math.round(Y(v)) + 0.5;
      g.beginPath(); g.moveTo(M.left, y); g.lineTo(M.left + pw, y); g.stroke();
      g.fillText(fmtNumber(v, tickDigits(min, max, Math.max(2, Math.floor(ph / 40)))), M.left - 6, y);
    }
    g.textAlign = 'center';
    g.textBaseline = 'top';
    const ticks = Math.max(2, Math.floor(pw / 110));
    for (let i = 0; i <= ticks; i++) {
      const t = this.from + (span * i) / ticks;
      const x = Math.round(X(t)) + 0.5;
      g.beginPath(); g.moveTo(x, M.top); g.lineTo(x, M.top + ph); g.stroke();
      g.textAlign = i === 0 ? 'left' : i === ticks ? 'right' : 'center';
      g.fillText(timeLabel(t, span), i === 0 ? x - 4 : i === ticks ? x + 4 : x, M.top + ph + 6);
    }
    g.strokeStyle = '#8a96a6';
    g.strokeRect(M.left + 0.5, M.top + 0.5, pw, ph);

    // Pens: min/max band, then the average line; gaps where a bucket is empty.
    g.save();
    g.beginPath(); g.rect(M.left, M.top, pw, ph); g.clip();
    for (const s of this.series) {
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
    if (this.cursorT !== null) {
      const x = Math.round(X(this.cursorT)) + 0.5;
      g.strokeStyle = '#1b2430';
      g.setLineDash([4, 3]);
      g.beginPath(); g.moveTo(x, M.top); g.lineTo(x, M.top + ph); g.stroke();
      g.setLineDash([]);
    }
    if (this.series.every((s) => s.buckets.every((b) => !b.count))) {
      g.fillStyle = '#5b6675';
      g.textAlign = 'center';
      g.textBaseline = 'middle';
      g.font = 'italic 13px system-ui, sans-serif';
      g.fillText('No data in this range', M.left + pw / 2, M.top + ph / 2);
    }
  }

  dispose() { this.ro.disconnect(); }
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

function timeLabel(t, span) {
  const d = new Date(t);
  const hm = `${pad(d.getHours())}:${pad(d.getMinutes())}`;
  if (span <= 10 * 60_000) return `${hm}:${pad(d.getSeconds())}`;
  if (span <= 36 * 3_600_000) return hm;
  return `${pad(d.getDate())}/${pad(d.getMonth() + 1)} ${hm}`;
}

export { fmtTime };
