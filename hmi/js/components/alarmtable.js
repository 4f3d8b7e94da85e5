// The alarm list as a table: used by the footer and the alarm screen's online view.

import { h, replace } from '../dom.js';
import { fmtTime, fmtValue } from '../format.js';

export const STATE_LABELS = {
  normal: 'Normal',
  unack_active: 'ACTIVE, unacked',
  ack_active: 'ACTIVE, acked',
  unack_rtn: 'Cleared, unacked',
  shelved: 'Shelved',
  suppressed: 'Suppressed',
  out_of_service: 'Out of service',
};

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

export function priorityClass(p) {
  return p >= 800 ? 'prio-urgent' : p >= 600 ? 'prio-high' : p >= 400 ? 'prio-medium' : 'prio-low';
}

function valueText(a) {
  if (a.value === null || a.value === undefined) return '';
  const v = fmtValue(a.value);
  const l = a.limit !== null && a.limit !== undefined && typeof a.limit !== 'boolean' ? ` (limit ${fmtValue(a.limit)})` : '';
  return `${v}${a.units ? ` ${a.units}` : ''}${l}`;
}

/**
 * Draws alarms into a <tbody>. `extra(a)` may return a cell with actions;
 * `selectable` adds a checkbox per row (named by alarm id).
 */
export function drawAlarmRows(tbody, alarms, { extra, selectable, selected } = {}) {
  replace(tbody, alarms.map((a) => {
    const row = h('tr', {
      class: ['alarm-row', a.acked ? 'acked' : 'unacked', a.active ? 'active' : 'cleared', priorityClass(a.priority), `state-${a.state}`],
      dataset: { alarmId: String(a.id) },
    });
    if (selectable) {
      row.append(h('td', {}, h('input', {
        type: 'checkbox', class: 'alarm-select', value: String(a.id),
        checked: selected && selected.has(a.id), 'aria-label': `Select alarm ${a.message}`,
      })));
    }
    row.append(
      h('td', { class: 'nowrap', text: fmtTime(a.active_since ?? a.last_change) }),
      h('td', { class: 'alarm-state', text: STATE_LABELS[a.state] || a.state }),
      h('td', { class: 'num', text: String(a.priority) }),
      h('td', { text: a.selection }),
      h('td', { text: KIND_LABELS[a.kind] || a.kind }),
      h('td', { class: 'alarm-message', text: a.message }),
      h('td', { class: 'nowrap', text: valueText(a) }));
    if (extra) row.append(h('td', { class: 'actions' }, extra(a)));
    return row;
  }));
  if (alarms.length === 0) {
    tbody.append(h('tr', {}, h('td', { colspan: 9, class: 'empty', text: 'No alarms match.' })));
  }
}

export const ALARM_HEADERS = ['Since', 'State', 'Prio', 'Selection', 'Type', 'Message', 'Value'];
