// Formatting of values, quality and times for display.

/** Role order, lowest first: the server enforces; the HMI only hides what would be refused. */
export const ROLES = ['display', 'guest', 'operator', 'supervisor', 'administrator'];
export const roleAtLeast = (role, min) => ROLES.indexOf(role) >= ROLES.indexOf(min);

export function pad(n, w = 2) { return String(n).padStart(w, '0'); }

/** Local date and time, "2026-11-21 06:55:03". */
export function fmtTime(ms, withMs = false) {
  if (ms === null || ms === undefined || !Number.isFinite(Number(ms))) return '—';
  const d = new Date(Number(ms));
  const t = `${d.getFullYear()}-${pad(d.getMonth() + 1)}-${pad(d.getDate())} ${pad(d.getHours())}:${pad(d.getMinutes())}:${pad(d.getSeconds())}`;
  return withMs ? `${t}.${pad(d.getMilliseconds(), 3)}` : t;
}

/** A number with a sensible number of decimals for its size. */
export function fmtNumber(v, digits) {
  if (typeof v !== 'number' || !Number.isFinite(v)) return String(v);
  if (digits === undefined) {
    const a = Math.abs(v);
    digits = a >= 1000 ? 0 : a >= 100 ? 1 : a >= 1 ? 2 : 3;
  }
  return v.toFixed(digits);
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
export function showSample(el, sample, { units = '', digits, live = true, format, kind } = {}) {
  const q = qualityOf(sample, live);
  // An integer tag (a counter) is shown without decimals.
  if (digits === undefined && kind === 'int') digits = 0;
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
