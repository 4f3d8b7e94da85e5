// Trend screen: several pens, X range by start date, start time and
// duration, one Y axis per unit (each automatic or set), pan and zoom back
// in time (drag, wheel, buttons; never into the future), live mode, a
// reading cursor, Show Tabular with Reload, and CSV export. The server downsamples to about one bucket
// per pixel, so long ranges stay light.

import { apiUrl, get, qs } from '../api.js';
import { h, replace, select, field } from '../dom.js';
import { dateFormat, decimalsOf, fmtDate, fmtNumber, fmtTime, pad, parseDateTime } from '../format.js';
import { live } from '../live.js';
import { dateInput, toast } from '../ui.js';
import { siteChoice } from '../sites.js';
import { TrendChart, PEN_COLORS, axesOf } from '../components/chart.js';
import { tagList } from './common.js';

const DURATIONS = [
  [5 * 60, '5 minutes'], [15 * 60, '15 minutes'], [3600, '1 hour'], [4 * 3600, '4 hours'],
  [8 * 3600, '8 hours'], [86400, '1 day'], [7 * 86400, '1 week'],
];
const LIVE_RELOAD_MS = 5000;
/** The narrowest and widest windows pan and zoom go to. */
const MIN_SPAN_S = 10;
const MAX_SPAN_S = 31 * 86400;
const MAX_PENS = 8;
const PENS_KEY = 'gridscada.trend.pens';

/** A Y bound for its field: four significant digits, whatever the pens' decimals (0.95 stays 0.95). */
const yBound = (v) => String(Number(v.toPrecision(4)));
const timeValue = (d) => `${pad(d.getHours())}:${pad(d.getMinutes())}:${pad(d.getSeconds())}`;
/** A point's width in time, as an operator says it: "2 s", "40 s", "3 min", "1 h". */
function fmtEvery(ms) {
  if (ms < 1000) return `${Math.max(1, Math.round(ms))} ms`;
  if (ms < 60_000) return `${Math.round(ms / 1000)} s`;
  if (ms < 3_600_000) return `${Math.round(ms / 60_000)} min`;
  return `${Math.round(ms / 3_600_000)} h`;
}

/** A duration in words for the duration list ("37 min 30 s", "2 h 15 min", "3 d 4 h"). */
function spanLabel(sec) {
  if (sec < 60) return `${sec} s`;
  if (sec < 3600) return `${Math.floor(sec / 60)} min${sec % 60 ? ` ${sec % 60} s` : ''}`;
  if (sec < 86400) return `${Math.floor(sec / 3600)} h${Math.floor((sec % 3600) / 60) ? ` ${Math.floor((sec % 3600) / 60)} min` : ''}`;
  return `${Math.floor(sec / 86400)} d${Math.floor((sec % 86400) / 3600) ? ` ${Math.floor((sec % 86400) / 3600)} h` : ''}`;
}

/**
 * The pens to start with: those named in the address (`#/trends?pens=A,B`,
 * as "Add to trend" opens it), else the last ones used here, else the first
 * two numeric tags with units (voltage and current first).
 */
function initialPens(meta) {
  const q = new URLSearchParams((location.hash.split('?')[1]) || '');
  const named = (q.get('pens') || '').split(',').map((t) => t.trim()).filter(Boolean);
  if (named.length) return named;
  try {
    const last = JSON.parse(localStorage.getItem(PENS_KEY) || '[]');
    if (Array.isArray(last) && last.some((t) => meta.has(t))) return last;
  } catch { /* ignore a bad stored value */ }
  const numeric = [...meta.values()].filter((t) => (t.kind === 'float' || t.kind === 'int') && t.units);
  const rank = (t) => (t.units === 'V' ? 0 : t.units === 'A' ? 1 : 2);
  return numeric.sort((a, b) => rank(a) - rank(b) || a.name.localeCompare(b.name)).slice(0, 2).map((t) => t.name);
}

export default {
  mount(el) {
    const pens = []; // {tag, color, units}
    let meta = new Map();
    let data = null; // {from, to, series}
    let liveTimer = null;
    let offTags = null;
    let offWant = null;
    let disposed = false;
    let loadSeq = 0;

    const now = new Date(Date.now() - 15 * 60_000);
    const startDate = dateInput({ id: 'trend-start-date' }, now);
    // Typed as 24-hour text: a time input follows the browser's locale (09:22:38 AM).
    const startTime = h('input', {
      type: 'text', id: 'trend-start-time', value: timeValue(now), size: 8, inputmode: 'numeric', placeholder: 'HH:MM:SS',
      pattern: '([01][0-9]|2[0-3]):[0-5][0-9](:[0-5][0-9])?', title: '24-hour time, HH:MM or HH:MM:SS',
    });
    const site = siteChoice('trend-site', () => load());
    const duration = select({ id: 'trend-duration' }, DURATIONS.map(([s, l]) => [String(s), l]), String(15 * 60));
    const liveBox = h('input', { type: 'checkbox', id: 'trend-live', checked: true });
    const yAxis = select({ id: 'trend-y-axis' }, [], '');
    const yAuto = h('input', { type: 'checkbox', id: 'trend-y-auto', checked: true });
    const yMin = h('input', { type: 'number', id: 'trend-y-min', step: 'any', disabled: true, size: 6 });
    const yMax = h('input', { type: 'number', id: 'trend-y-max', step: 'any', disabled: true, size: 6 });
    const penInput = h('input', { id: 'trend-pen-input', list: 'trend-tag-list', placeholder: 'Tag name (type to search)', size: 24 });
    const datalist = h('datalist', { id: 'trend-tag-list' });
    const penList = h('ul', { class: 'pen-list', id: 'trend-pens', 'aria-label': 'Pens' });
    const readout = h('dl', { class: 'kv cursor-readout', id: 'trend-cursor', 'aria-live': 'polite' });
    const canvas = h('canvas', { id: 'trend-canvas' });
    const tableBox = h('div', { class: 'table-wrap', id: 'trend-table', tabindex: '0', hidden: true });
    const tableBtn = h('button', { type: 'button', class: 'btn', id: 'trend-show-table', 'aria-pressed': 'false', text: 'Show Tabular' });
    const reloadBtn = h('button', { type: 'button', class: 'btn', id: 'trend-reload', text: 'Reload' });
    const csvLink = h('a', { class: 'btn', id: 'trend-csv', href: '#', download: 'trend.csv', text: 'Export CSV' });
    const status = h('p', { class: 'hint', id: 'trend-status', role: 'status' });
    const axesList = h('ul', { class: 'axes-list', id: 'trend-axes', 'aria-label': 'Y axes' });
    const navBtn = (id, text, title, f) => h('button', { type: 'button', class: 'btn btn-small', id, title, 'aria-label': title, text, onclick: f });
    const nav = h('div', { class: 'btn-row trend-nav', role: 'group', 'aria-label': 'Move the window' },
      navBtn('trend-back', '◀ Back', 'Back in time by half the window', () => chart.pan(-0.5)),
      navBtn('trend-zoom-in', '+ Zoom in', 'Zoom in (half the window)', () => chart.zoom(0.5)),
      navBtn('trend-zoom-out', '− Zoom out', 'Zoom out (twice the window)', () => chart.zoom(2)),
      navBtn('trend-forward', 'Forward ▶', 'Forward in time by half the window (never past now)', () => chart.pan(0.5)));

    const chart = new TrendChart(canvas, { onCursor: drawReadout, onView: ({ from, to, kind }) => setWindow(from, to - from, kind) });

    el.append(
      h('h1', { class: 'screen-title', text: 'Trends' }),
      h('div', { class: 'card' },
        h('div', { class: 'filters' },
          field('Start date', startDate), field('Start time', startTime), field('Duration', duration),
          h('label', { class: 'field field-inline' }, liveBox, 'Live'),
          field('Y axis', yAxis),
          h('label', { class: 'field field-inline' }, yAuto, 'Y automatic'),
          field('Y min', yMin), field('Y max', yMax), site.el,
          h('div', { class: 'btn-row' }, h('button', { type: 'button', class: 'btn btn-primary', id: 'trend-apply', onclick: () => load(), text: 'Apply' }), reloadBtn, tableBtn, csvLink))),
      h('div', { class: 'trend-layout' },
        h('div', { class: 'card' }, nav, h('div', { class: 'trend-canvas-wrap' }, canvas), status, axesList, tableBox),
        h('div', { class: 'card' },
          h('h2', { text: 'Pens' }), penList,
          h('form', { class: 'btn-row', id: 'trend-add-pen' }, h('label', { class: 'field' }, h('span', { class: 'field-label', text: 'Add pen' }), penInput), datalist,
            h('button', { type: 'submit', class: 'btn btn-small', text: 'Add' })),
          h('h2', { text: 'Cursor' }), readout)));

    el.querySelector('#trend-add-pen').addEventListener('submit', (e) => {
      e.preventDefault();
      const name = penInput.value.trim();
      if (!name) return;
      if (!meta.has(name)) { toast(`No numeric tag named "${name}".`, 'error'); return; }
      if (pens.some((p) => p.tag === name)) return;
      if (pens.length >= MAX_PENS) { toast(`At most ${MAX_PENS} pens.`, 'error'); return; }
      addPen(name);
      penInput.value = '';
      load();
    });
    yAuto.addEventListener('change', () => {
      yMin.disabled = yMax.disabled = yAuto.checked;
      if (!yAuto.checked && data) {
        const r = chart.yRange(yAxis.value);
        yMin.value = yBound(r.min); yMax.value = yBound(r.max);
      }
      applyY();
    });
    for (const i of [yMin, yMax]) i.addEventListener('change', applyY);
    // The Y fields show and set the axis chosen.
    yAxis.addEventListener('change', () => {
      const fixed = chart.yFixed.get(yAxis.value);
      yAuto.checked = !fixed;
      yMin.disabled = yMax.disabled = !fixed;
      yMin.value = fixed ? yBound(fixed.min) : '';
      yMax.value = fixed ? yBound(fixed.max) : '';
    });
    liveBox.addEventListener('change', () => { setLive(liveBox.checked); load(); });
    // Editing the start leaves Live and keeps what was typed (the window starts there).
    for (const i of [startDate, startTime, duration]) {
      i.addEventListener('change', () => {
        if (i !== duration && liveBox.checked) { liveBox.checked = false; setLive(false, false); }
        load();
      });
    }
    reloadBtn.addEventListener('click', () => load());
    tableBtn.addEventListener('click', () => {
      tableBox.hidden = !tableBox.hidden;
      tableBtn.setAttribute('aria-pressed', String(!tableBox.hidden));
      tableBtn.textContent = tableBox.hidden ? 'Show Tabular' : 'Hide Tabular';
      drawTable();
    });

    function applyY() {
      const lo = Number(yMin.value);
      const hi = Number(yMax.value);
      if (yAuto.checked) chart.setY(yAxis.value, null);
      else if (yMin.value !== '' && yMax.value !== '' && lo < hi) chart.setY(yAxis.value, { min: lo, max: hi });
      else toast('Y range: the minimum must be below the maximum.', 'error');
      drawAxes();
    }

    /** The axes in words: each unit, its side, its range, and its pens. */
    function drawAxes() {
      const axes = chart.axesInfo();
      replace(axesList, axes.map((a) => h('li', { dataset: { unit: a.unit, side: a.side, min: String(a.min), max: String(a.max), pens: a.pens.join(',') } },
        h('strong', { text: a.unit || '(no unit)' }), ` axis, ${a.side}: ${yBound(a.min)} to ${yBound(a.max)}${chart.yFixed.has(a.unit) ? ' (set)' : ''}; ${a.pens.join(', ')}`)));
      // The Y axis choice follows the units of the pens.
      const units = axesOf(pens).map((a) => a.unit);
      const cur = yAxis.value;
      if ([...yAxis.options].map((o) => o.value).join('\n') !== units.join('\n')) {
        replace(yAxis, units.map((u) => h('option', { value: u, selected: u === cur, text: u || '(no unit)' })));
      }
    }

    /**
     * Shows the window that starts at `from` and lasts `dur` ms (from pan or
     * zoom), never reaching past now. A zoom of the live window stays live
     * (it keeps its end, now); a pan leaves Live, as a typed start does.
     */
    function setWindow(from, dur, kind) {
      const now = Date.now();
      let sec = Math.round(Math.min(MAX_SPAN_S, Math.max(MIN_SPAN_S, dur / 1000)));
      let start = Math.floor(from / 1000) * 1000;
      if (start + sec * 1000 > now) start = Math.floor((now - sec * 1000) / 1000) * 1000;
      const stayLive = liveBox.checked && kind === 'zoom';
      setDuration(sec);
      if (!stayLive) {
        if (liveBox.checked) { liveBox.checked = false; setLive(false, false); }
        const d = new Date(start);
        startDate.value = fmtDate(d);
        startTime.value = timeValue(d);
      }
      load();
    }

    /** Sets the duration list, with the window's own length as an extra entry when it is none of the usual. */
    function setDuration(sec) {
      const v = String(sec);
      for (const o of [...duration.options]) if (o.dataset.custom && o.value !== v) o.remove();
      if (![...duration.options].some((o) => o.value === v)) {
        const opt = h('option', { value: v, dataset: { custom: '1' }, text: spanLabel(sec) });
        const after = [...duration.options].find((o) => Number(o.value) > sec);
        duration.insertBefore(opt, after || null);
      }
      duration.value = v;
    }

    function addPen(tag) {
      const used = new Set(pens.map((p) => p.color));
      const color = PEN_COLORS.find((c) => !used.has(c)) || PEN_COLORS[pens.length % PEN_COLORS.length];
      pens.push({ tag, color, units: (meta.get(tag) || {}).units || '' });
      drawPens();
    }

    function drawPens() {
      try { localStorage.setItem(PENS_KEY, JSON.stringify(pens.map((p) => p.tag))); } catch { /* private mode */ }
      replace(penList, pens.map((p) => {
        const sw = h('span', { class: 'pen-swatch' });
        sw.style.background = p.color;
        // The pen's words and its tag, both whole (wrapped, never cut short).
        const desc = (meta.get(p.tag) || {}).description || '';
        const units = p.units ? ` (${p.units})` : '';
        return h('li', { dataset: { pen: p.tag } }, sw, h('span', { class: 'pen-name', title: `${desc ? `${desc}: ` : ''}${p.tag}${units}` },
          desc ? [h('span', { class: 'pen-desc', text: `${desc}${units}` }), h('span', { class: 'pen-tag', text: p.tag })] : `${p.tag}${units}`),
          h('button', { type: 'button', class: 'btn btn-small', 'aria-label': `Remove pen ${p.tag}`, text: '×',
            onclick: () => { pens.splice(pens.indexOf(p), 1); drawPens(); load(); } }));
      }));
      if (!pens.length) penList.append(h('li', { class: 'empty', text: 'No pens: add a tag below.' }));
      resubscribe();
    }

    function range() {
      const dur = Number(duration.value) * 1000;
      if (liveBox.checked) {
        const to = Date.now();
        return { from: to - dur, to };
      }
      const time = (startTime.value || '00:00:00').trim();
      if (!/^([01][0-9]|2[0-3]):[0-5][0-9](:[0-5][0-9])?$/.test(time)) return { from: NaN, to: NaN };
      const from = parseDateTime(`${startDate.value} ${time}`) ?? NaN;
      return { from, to: from + dur };
    }

    async function load() {
      const { from, to } = range();
      if (!Number.isFinite(from)) { status.textContent = `Set a valid start date (${dateFormat()}) and a 24-hour start time (HH:MM:SS).`; return; }
      csvLink.href = pens.length ? apiUrl(`/api/trends.csv${qs({ tags: pens.map((p) => p.tag).join(','), from, to, site: site.value() })}`) : '#';
      if (!pens.length) { data = { from, to, series: [] }; chart.setData([], from, to); drawAxes(); drawTable(); return; }
      const points = Math.max(50, Math.min(2000, Math.round(canvas.clientWidth || 800)));
      const seq = ++loadSeq;
      status.textContent = 'Loading…';
      try {
        const r = await get(`/api/trends${qs({ tags: pens.map((p) => p.tag).join(','), from, to, points, site: site.value() })}`);
        if (disposed || seq !== loadSeq) return;
        const series = pens.map((p) => {
          const s = (r.series || []).find((x) => x.tag === p.tag);
          return { ...p, buckets: s ? s.buckets : [] };
        });
        data = { from, to, series };
        chart.setData(series, from, to);
        canvas.dataset.from = String(from);
        canvas.dataset.to = String(to);
        drawAxes();
        const n = series.reduce((a, s) => a + s.buckets.reduce((b, k) => b + (k.count || 0), 0), 0);
        status.textContent = `${fmtTime(from)} to ${fmtTime(to)}: ${n} samples, drawn as one point every ${fmtEvery((to - from) / points)} (the average, in a band from the lowest to the highest)${liveBox.checked ? ' (live)' : ''}.`;
        drawTable();
      } catch (e) {
        if (seq === loadSeq) status.textContent = `Cannot load the trend: ${e.detail}`;
      }
    }

    // Live mode: between reloads, the newest live values extend the pens
    // (this server's values: not onto another site's trend).
    function resubscribe() {
      if (offWant) offWant();
      offWant = live.want({ tags: pens.map((p) => p.tag) });
    }
    function onLiveTags(names) {
      if (!liveBox.checked || !data || site.other()) return;
      let changed = false;
      for (const s of data.series) {
        if (!names.includes(s.tag)) continue;
        const v = live.get(s.tag);
        if (!v || typeof v.value !== 'number' || !v.quality || v.quality.code === 'bad') continue;
        const t = v.timestamp;
        const last = s.buckets[s.buckets.length - 1];
        if (last && t < last.end) continue;
        s.buckets.push({ start: t, end: t + 1, count: 1, min: v.value, max: v.value, avg: v.value, last: v.value, last_ts: t });
        changed = true;
      }
      if (changed) {
        const span = data.to - data.from;
        data.to = Date.now();
        data.from = data.to - span;
        chart.setData(data.series, data.from, data.to);
        canvas.dataset.from = String(data.from);
        canvas.dataset.to = String(data.to);
        drawAxes();
      }
    }
    function setLive(on, freeze = true) {
      clearInterval(liveTimer);
      chart.anchorEnd = on;
      liveTimer = on ? setInterval(load, LIVE_RELOAD_MS) : null;
      if (!on && freeze) {
        // Freeze the window that was on view (never one reaching into the
        // future), so the fields say what is shown.
        const dur = Number(duration.value) * 1000;
        const latest = Math.floor((Date.now() - dur) / 1000) * 1000;
        const d = new Date(Math.min(data ? data.from : latest, latest));
        startDate.value = fmtDate(d);
        startTime.value = timeValue(d);
      }
    }

    function drawReadout({ t, values }) {
      replace(readout, h('dt', { text: 'Time' }), h('dd', { id: 'trend-cursor-time', text: fmtTime(t) }),
        values.map((v) => {
          const sw = h('span', { class: 'pen-swatch' });
          sw.style.background = v.color;
          const b = v.bucket;
          // Inside a bucket its average; after it, the value held since its last sample.
          const val = b ? (t >= b.end && typeof b.last === 'number' ? b.last : b.avg) : null;
          const digits = decimalsOf(v.tag);
          const text = b ? `${fmtNumber(val, digits)}${v.units ? ` ${v.units}` : ''}` : '? no data';
          return [h('dt', {}, sw, v.tag), h('dd', { class: ['value', b ? 'q-good' : 'q-bad'], dataset: { pen: v.tag },
            title: b ? `min ${fmtNumber(b.min, digits)}, max ${fmtNumber(b.max, digits)}, ${b.count} samples, ${fmtTime(b.start)} to ${fmtTime(b.end)}` : 'no samples at this time',
            text })];
        }));
    }

    function drawTable() {
      if (tableBox.hidden || !data) return;
      const series = data.series;
      const times = series.length ? series[0].buckets.map((b) => b.start) : [];
      const rows = times.map((t, i) => h('tr', {}, h('td', { class: 'nowrap', text: fmtTime(t) }),
        series.map((s) => {
          const b = s.buckets[i];
          const digits = decimalsOf(s.tag);
          return h('td', { class: 'num', title: b && b.count ? `min ${fmtNumber(b.min, digits)}, max ${fmtNumber(b.max, digits)}, ${b.count} samples` : '', text: b && b.count ? fmtNumber(b.avg, digits) : '—' });
        })));
      const withData = rows.filter((_, i) => series.some((s) => s.buckets[i] && s.buckets[i].count));
      replace(tableBox, h('table', { class: 'data', id: 'trend-data-table' },
        h('thead', {}, h('tr', {}, h('th', { scope: 'col', text: 'Bucket start' }), series.map((s) => h('th', { scope: 'col', class: 'num', text: `${s.tag}${s.units ? ` (${s.units})` : ''} avg` })))),
        h('tbody', {}, withData.length ? withData : h('tr', {}, h('td', { colspan: series.length + 1, class: 'empty', text: 'No data in this range.' })))));
    }

    offTags = live.onTags(onLiveTags);
    (async () => {
      try {
        const tags = await tagList();
        meta = new Map(tags.filter((t) => t.kind === 'float' || t.kind === 'int' || t.kind === 'bool').map((t) => [t.name, t]));
        replace(datalist, [...meta.keys()].sort().map((n) => h('option', { value: n })));
      } catch (e) {
        status.textContent = `Cannot list tags: ${e.detail}`;
      }
      if (disposed) return;
      for (const t of initialPens(meta)) if (meta.has(t) && pens.length < MAX_PENS) addPen(t);
      setLive(true);
      load();
    })();

    return () => {
      disposed = true;
      clearInterval(liveTimer);
      if (offTags) offTags();
      if (offWant) offWant();
      chart.dispose();
    };
  },
};
