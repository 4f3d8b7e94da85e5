// The alarm list as a table: used by the footer and the alarm screen's online view.

import { h, replace } from '../dom.js';
import { decimalsOf, fmtTime, fmtValue } from '../format.js';

export const STATE_LABELS = {
  normal: 'Normal',
  unack_active: 'ACTIVE, unacked',
  ack_active: 'ACTIVE, acked',
  unack_rtn: 'Cleared, unacked',
  shelved: 'Shelved',
  suppressed: 'Suppressed',
  out_of_service: 'Out of service',
};

/** The overlay states: an alarm in them is not annunciated. */
const HIDDEN_WORDS = { suppressed: 'suppressed', shelved: 'shelved', out_of_service: 'out of service' };

/**
 * Why a history row happened, in words, from its cause and the state it went
 * to: an activation or a return while suppressed (or shelved, or out of
 * service) leaves the state as it was, and only the cause tells them apart.
 * Rows recorded before causes were kept have none: ''.
 */
export function causeLabel(t) {
  const hidden = HIDDEN_WORDS[t.to_state];
  switch (t.cause) {
    case 'activate': return hidden ? `Activated while ${hidden}` : 'Activated';
    case 'return': return hidden ? `Returned to normal while ${hidden}` : 'Returned to normal';
    case 'ack': return 'Acknowledged';
    case 'shelve': return 'Shelved';
    case 'unshelve': return 'Unshelved';
    case 'shelve_expired': return 'Shelving expired';
    case 'suppress': return 'Suppressed by design';
    case 'unsuppress': return 'Suppression lifted';
    case 'out_of_service': return 'Taken out of service';
    case 'in_service': return 'Returned to service';
    case null: case undefined: case '': return '';
    default: return String(t.cause);
  }
}

/** A history row's states: "A → B" when it changed, else the one state. */
export function stateChange(t) {
  const from = STATE_LABELS[t.from_state] || t.from_state;
  const to = STATE_LABELS[t.to_state] || t.to_state;
  return t.from_state === t.to_state ? to : `${from} → ${to}`;
}

export const KIND_LABELS = { hi: 'Hi', lo: 'Lo', hihi: 'HiHi', lolo: 'LoLo', discrete: 'Discrete', comm: 'Comm failure', comm_fail: 'Comm failure', system: 'System' };

/** Sort: unacknowledged first, then active, then priority (high first), then newest. */
export function sortAlarms(list) {
  return [...list].sort((a, b) =>
    (a.acked - b.acked) || (b.active - a.active) || (b.priority - a.priority) || (b.last_change - a.last_change));
}

export function filterAlarms(list, { selection, minPriority, text } = {}) {
  const t = (text || '').toLowerCase();
  return list.filter((a) =>
    (!selection || String(a.selection).toLowerCase() === selection.toLowerCase()) &&
    (!minPriority || a.priority >= minPriority) &&
    (!t || `${a.message} ${a.tag || ''} ${a.key}`.toLowerCase().includes(t)));
}

/**
 * The four priority bands, highest first: each has a colour AND a shape
 * (docs/HMI_STYLE.md), so priority never rests on colour alone.
 */
export const PRIORITY_BANDS = [
  { key: 'urgent', label: 'Urgent', min: 800, glyph: '◆' },
  { key: 'high', label: 'High', min: 600, glyph: '▲' },
  { key: 'medium', label: 'Medium', min: 400, glyph: '■' },
  { key: 'low', label: 'Low', min: -Infinity, glyph: '●' },
];

export function priorityBand(p) {
  return PRIORITY_BANDS.find((b) => p >= b.min);
}

export function priorityClass(p) {
  return `prio-${priorityBand(p).key}`;
}

/** A priority as a chip: the band's shape and colour, with the number. */
export function priorityChip(p, text = String(p)) {
  return bandChip(priorityBand(p), text, `${priorityBand(p).label} priority (${p})`);
}

function bandChip(b, text, title) {
  return h('span', { class: ['prio-chip', `prio-${b.key}`], title, dataset: { band: b.key } },
    h('span', { class: 'prio-glyph', 'aria-hidden': 'true', text: b.glyph }), h('span', { class: 'prio-text', text }));
}

/**
 * Alarm counts by priority band for each selection (area): [{selection,
 * urgent, high, medium, low, total, unacked}], by selection name, and the totals.
 */
export function summarize(list) {
  const rows = new Map();
  const blank = (selection) => ({ selection, urgent: 0, high: 0, medium: 0, low: 0, total: 0, unacked: 0 });
  const all = blank('All');
  for (const a of list) {
    const sel = String(a.selection ?? '');
    if (!rows.has(sel)) rows.set(sel, blank(sel));
    const k = priorityBand(a.priority).key;
    for (const r of [rows.get(sel), all]) {
      r[k] += 1;
      r.total += 1;
      if (!a.acked) r.unacked += 1;
    }
  }
  return { rows: [...rows.values()].sort((x, y) => x.selection.localeCompare(y.selection)), all };
}

/**
 * The alarm summary per area as a table: a row per selection, a column per
 * priority band (its shape and colour in the header), unacknowledged and
 * total. `onPick(selection)` (optional) makes each area a button.
 */
export function summaryTable(list, { id, onPick, current } = {}) {
  const { rows, all } = summarize(list);
  const cell = (n, b) => h('td', { class: ['num', n ? `sum-${b.key}` : 'sum-zero'], dataset: { band: b.key } },
    n ? bandChip(b, String(n), `${n} ${b.label.toLowerCase()} priority`) : '0');
  const line = (r, isAll) => h('tr', { dataset: { selection: isAll ? '' : r.selection }, class: isAll ? 'sum-all' : '', 'aria-current': !isAll && current === r.selection ? 'true' : null },
    h('th', { scope: 'row' }, onPick
      ? h('button', { type: 'button', class: 'link-btn', onclick: () => onPick(isAll ? '' : r.selection), text: isAll ? 'All areas' : r.selection, title: isAll ? 'Show every area' : `Show the alarms of ${r.selection}` })
      : (isAll ? 'All areas' : r.selection)),
    PRIORITY_BANDS.map((b) => cell(r[b.key], b)),
    h('td', { class: ['num', r.unacked ? 'sum-unacked' : 'sum-zero'], text: String(r.unacked) }),
    h('td', { class: 'num', text: String(r.total) }));
  return h('table', { class: 'data alarm-summary', id },
    h('caption', { class: 'sr-only', text: 'Standing alarms by area and priority' }),
    h('thead', {}, h('tr', {}, h('th', { scope: 'col', text: 'Area' }),
      PRIORITY_BANDS.map((b) => h('th', { scope: 'col', class: 'num', title: `${b.label} priority${Number.isFinite(b.min) ? ` (${b.min} and above)` : ''}` },
        h('span', { class: ['prio-glyph', `prio-fg-${b.key}`], 'aria-hidden': 'true', text: b.glyph }), ` ${b.label}`)),
      h('th', { scope: 'col', class: 'num', text: 'Unacked' }), h('th', { scope: 'col', class: 'num', text: 'Total' }))),
    h('tbody', {}, rows.length ? rows.map((r) => line(r, false)) : h('tr', {}, h('td', { colspan: 7, class: 'empty', text: 'No standing alarms.' }))),
    rows.length > 1 ? h('tfoot', {}, line(all, true)) : null);
}

/** A number as the server writes it into a message: at most two decimals. */
function messageNumber(v) {
  if (typeof v !== 'number' || !Number.isFinite(v)) return fmtValue(v);
  const s = v.toFixed(2).replace(/\.?0+$/, '');
  return s === '-0' ? '0' : s;
}

function valueText(a) {
  if (a.value === null || a.value === undefined) return '';
  // The tag's own word for the value (TRIPPED), else the number.
  // In the tag's decimals where the HMI has read them, else the plant's.
  const digits = decimalsOf(a.tag);
  const v = a.value_text || fmtValue(a.value, digits);
  const l = a.limit !== null && a.limit !== undefined && typeof a.limit !== 'boolean' ? ` (limit ${fmtValue(a.limit, digits)})` : '';
  return `${v}${a.units ? ` ${a.units}` : ''}${l}`;
}

/**
 * The value at the latest activation, written as the message writes it (the
 * message's value is substituted at activation), or '' when unknown or no
 * different from the value now.
 */
function activationText(a) {
  const at = a.activation_value;
  if (at === null || at === undefined) return '';
  const word = (v, text) => text || messageNumber(v);
  const then = word(at, a.activation_value_text);
  if (a.value !== null && a.value !== undefined && word(a.value, a.value_text) === then) return '';
  return `${then}${a.units ? ` ${a.units}` : ''}`;
}

/**
 * The "Value now" cell: the tag's value now (and the limit); below it, when
 * it differs, the value at activation, which is the one the message shows,
 * so "0 V" in the message beside 231 here is never left unexplained.
 */
function valueCell(a) {
  const at = activationText(a);
  return h('td', { class: 'nowrap alarm-value' },
    h('span', { class: 'alarm-value-now', text: valueText(a) }),
    at ? h('span', { class: 'alarm-value-activation', title: 'The value when the alarm activated, as its message shows it', text: `at activation: ${at}` }) : null);
}

/**
 * Draws alarms into a <tbody>. `extra(a)` may return a cell with actions;
 * `selectable` adds a checkbox per row (named by alarm id). `limit` draws
 * only the first rows (a flood of standing alarms would otherwise put tens
 * of thousands of rows into the page at every change); a last row then
 * counts the rest, followed by what `more(count)` gives (a link, a button).
 */
export function drawAlarmRows(tbody, alarms, { extra, selectable, selected, limit = Infinity, more } = {}) {
  const drawn = alarms.length > limit ? alarms.slice(0, limit) : alarms;
  replace(tbody, drawn.map((a) => {
    const row = h('tr', {
      class: ['alarm-row', a.acked ? 'acked' : 'unacked', a.active ? 'active' : 'cleared', priorityClass(a.priority), `state-${a.state}`],
      dataset: { alarmId: String(a.id) },
    });
    if (selectable) {
      row.append(h('td', { class: 'alarm-pick' }, h('input', {
        type: 'checkbox', class: 'alarm-select', value: String(a.id),
        checked: selected && selected.has(a.id), 'aria-label': `Select alarm ${a.message}`,
      })));
    }
    row.append(
      // Since: when it became active, also once it cleared; Cleared: when.
      h('td', { class: 'nowrap alarm-since', text: fmtTime(a.activated_at ?? a.active_since ?? a.last_change) }),
      h('td', { class: 'nowrap alarm-cleared', text: a.active || !a.cleared_at ? '' : fmtTime(a.cleared_at) }),
      h('td', { class: 'alarm-state', text: STATE_LABELS[a.state] || a.state }),
      h('td', { class: 'num alarm-prio' }, priorityChip(a.priority)),
      h('td', { class: 'alarm-selection', text: a.selection }),
      h('td', { class: 'alarm-kind', text: KIND_LABELS[a.kind] || a.kind }),
      h('td', { class: 'alarm-message', text: a.message }),
      valueCell(a));
    if (extra) row.append(h('td', { class: 'actions' }, extra(a)));
    return row;
  }));
  if (alarms.length === 0) {
    tbody.append(h('tr', {}, h('td', { colspan: 10, class: 'empty', text: 'No alarms match.' })));
  } else if (drawn.length < alarms.length) {
    const left = alarms.length - drawn.length;
    tbody.append(h('tr', { class: 'alarm-more' }, h('td', { colspan: 10, class: 'empty' },
      `${left} more alarm${left === 1 ? '' : 's'}`, more ? more(left) : ' not drawn.')));
  }
}

// "Value now": the message keeps the value at activation; the value cell shows both, labelled.
export const ALARM_HEADERS = ['Since', 'Cleared', 'State', 'Prio', 'Selection', 'Type', 'Message', 'Value now'];
