// Formatting of values, quality and times for display.

/** Role order, lowest first: the server enforces; the HMI only hides what would be refused. */
export const ROLES = ['display', 'guest', 'operator', 'supervisor', 'administrator'];
export const roleAtLeast = (role, min) => ROLES.indexOf(role) >= ROLES.indexOf(min);

export function pad(n, w = 2) { return String(n).padStart(w, '0'); }

/**
 * The plant's display settings (`[hmi]`, sent with GET /api/session): the
 * decimals of an analog value whose tag sets none, and the date order.
 */
const display = { decimals: 1, dateFormat: 'YYYY-MM-DD' };

/** Takes the session's `hmi` settings; missing ones keep their defaults. */
export function setDisplay(hmi) {
  if (!hmi) return;
  if (Number.isInteger(hmi.decimals)) display.decimals = hmi.decimals;
  if (typeof hmi.date_format === 'string') display.dateFormat = hmi.date_format;
}

/** The configured date pattern, e.g. "DD.MM.YYYY". */
export const dateFormat = () => display.dateFormat;

/** A local date in the plant's order, "2026-11-21" or "21.11.2026"; without the year: "21.11". */
export function fmtDate(d, { year = true } = {}) {
  const pattern = year ? display.dateFormat : display.dateFormat.replace(/[^A-Z]?YYYY[^A-Z]?/, '');
  return pattern.replace('YYYY', String(d.getFullYear())).replace('MM', pad(d.getMonth() + 1)).replace('DD', pad(d.getDate()));
}

/** A date typed in the plant's order, as "YYYY-MM-DD"; null when it is not one. */
export function parseDate(text) {
  const order = display.dateFormat.match(/YYYY|MM|DD/g);
  const parts = String(text).trim().match(/^(\d{1,4})\D(\d{1,2})\D(\d{1,4})$/);
  if (!parts) return null;
  const by = Object.fromEntries(order.map((k, i) => [k, Number(parts[i + 1])]));
  const d = new Date(by.YYYY, by.MM - 1, by.DD);
  if (by.YYYY < 1000 || d.getMonth() !== by.MM - 1 || d.getDate() !== by.DD) return null;
  return `${by.YYYY}-${pad(by.MM)}-${pad(by.DD)}`;
}

/** The `pattern` of a field a date is typed in, in the plant's order. */
export function datePattern() {
  return display.dateFormat.replace(/[.]/g, '\\.').replace('YYYY', '[0-9]{4}').replace(/MM|DD/g, '[0-9]{1,2}');
}

/** A local time typed as a date in the plant's order and a 24-hour time ("21.11.2026 14:05[:03]"; the date alone: midnight), in ms; null when it is not one. */
export function parseDateTime(text) {
  const [date, time = '00:00', ...rest] = String(text).trim().split(/\s+/);
  const iso = parseDate(date);
  const t = time.match(/^([01]?\d|2[0-3]):([0-5]\d)(?::([0-5]\d))?$/);
  if (!iso || !t || rest.length) return null;
  return new Date(`${iso}T${pad(Number(t[1]))}:${t[2]}:${t[3] || '00'}`).getTime();
}

/** Local date and 24-hour time, "2026-11-21 06:55:03" (the date in the plant's order). */
export function fmtTime(ms, withMs = false) {
  if (ms === null || ms === undefined || !Number.isFinite(Number(ms))) return '—';
  const d = new Date(Number(ms));
  const t = `${fmtDate(d)} ${pad(d.getHours())}:${pad(d.getMinutes())}:${pad(d.getSeconds())}`;
  return withMs ? `${t}.${pad(d.getMilliseconds(), 3)}` : t;
}

/**
 * Decimals of the tags whose metadata the HMI has read (`decimals` of
 * GET /api/tags: the tag's own, else the plant's; null for a bool or text).
 * Values of one tag are then shown alike on every screen.
 */
const tagDecimals = new Map();
const decimalsListeners = new Set();

/** Records the decimals of tags as the API lists them; tells the listeners when any is new. */
export function noteTags(tags) {
  let changed = false;
  for (const t of tags || []) {
    if (!t || typeof t.name !== 'string' || !('decimals' in t) || tagDecimals.get(t.name) === t.decimals) continue;
    tagDecimals.set(t.name, t.decimals);
    changed = true;
  }
  if (changed) for (const f of decimalsListeners) f();
  return tags;
}

/** The decimals a tag's values are shown with, if known. */
export function decimalsOf(tag) {
  const d = tagDecimals.get(tag);
  return Number.isInteger(d) ? d : undefined;
}

/** Calls f when decimals of more tags become known; returns a function that stops it. */
export function onDecimals(f) { decimalsListeners.add(f); return () => decimalsListeners.delete(f); }

/** A number with the given decimals, else the plant's (`[hmi] decimals`), so a screen's numbers line up. */
export function fmtNumber(v, digits) {
  if (typeof v !== 'number' || !Number.isFinite(v)) return String(v);
  return v.toFixed(digits ?? display.decimals);
}

export function fmtValue(v, digits) {
  if (v === null || v === undefined) return '—';
  if (typeof v === 'boolean') return v ? 'TRUE' : 'FALSE';
  if (typeof v === 'number') return fmtNumber(v, digits);
  return String(v);
}

/**
 * The configured word for a value (a tag's `states`, e.g. {false: "OPEN",
 * true: "CLOSED"}), or undefined: a boolean by "true"/"false", else by
 * "1"/"0"; a whole number by its digits. The server's `state_label` does the same.
 */
export function stateWord(states, v) {
  if (!states) return undefined;
  if (typeof v === 'boolean') return states[String(v)] ?? states[v ? '1' : '0'];
  if (typeof v === 'number' && Number.isInteger(v)) return states[String(v)];
  return undefined;
}

/** A value in the tag's words where it has them, else as a value. */
export function fmtStated(states, v, digits) {
  return stateWord(states, v) ?? fmtValue(v, digits);
}

/** Samples older than this while the source claims Good are shown as stale. */
export const STALE_MS = 60_000;

/**
 * How a sample should look: { cls: 'q-good'|'q-uncertain'|'q-bad', usable, reason }.
 * `usable` is false for Bad or missing values, which are never shown as a plain number.
 */
export function qualityOf(sample, live = true) {
  if (!sample) return { cls: 'q-bad', usable: false, reason: 'no value received' };
  const q = sample.quality || {};
  if (!live) return { cls: 'q-uncertain', usable: false, reason: 'not live: the connection to the server is lost' };
  if (q.code === 'bad') return { cls: 'q-bad', usable: false, reason: q.reason || 'bad quality' };
  if (q.code === 'uncertain') return { cls: 'q-uncertain', usable: true, reason: q.reason || 'uncertain quality' };
  return { cls: 'q-good', usable: true, reason: '' };
}

/**
 * Shows a sample in an element: the value and units, or "?" greyed with the
 * reason in its title when the value may not be trusted.
 */
export function showSample(el, sample, { units = '', digits, live = true, format, kind, tag } = {}) {
  const q = qualityOf(sample, live);
  // The tag's configured decimals; an integer tag (a counter) has none.
  if (digits === undefined) digits = decimalsOf(tag) ?? (kind === 'int' ? 0 : undefined);
  el.classList.remove('q-good', 'q-uncertain', 'q-bad');
  el.classList.add('value', q.cls);
  const shown = sample && sample.value !== undefined && sample.value !== null
    ? (format ? format(sample.value) : fmtValue(sample.value, digits)) : '';
  if (!q.usable) {
    el.textContent = shown ? `? ${shown}` : '?';
    el.title = `${q.reason}${sample && sample.timestamp ? ` (last update ${fmtTime(sample.timestamp)})` : ''}`;
    el.setAttribute('aria-label', `unknown: ${q.reason}`);
  } else {
    el.textContent = units ? `${shown} ${units}` : shown;
    el.title = q.reason ? `${q.reason} (${fmtTime(sample.timestamp)})` : `updated ${fmtTime(sample.timestamp)}`;
    if (q.cls === 'q-uncertain') el.textContent += ' ~';
    el.removeAttribute('aria-label');
  }
}

/** Duration in seconds, e.g. "1 h 05 min". */
export function fmtDuration(s) {
  if (!Number.isFinite(s)) return '—';
  if (s < 60) return `${s.toFixed(s < 10 ? 1 : 0)} s`;
  const m = Math.floor(s / 60);
  if (m < 60) return `${m} min ${pad(Math.round(s % 60))} s`;
  return `${Math.floor(m / 60)} h ${pad(m % 60)} min`;
}
