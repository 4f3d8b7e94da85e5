// Alarm KPIs: the ISA-18.2 performance figures of a time range (the last
// day, week or 30 days), each held against its target, for the supervisor
// running alarm rationalisation: the rate per operator per 10 minutes (and
// per selection, the area one console watches), floods, the 10 most frequent
// alarms, chattering, stale and shelved alarms.

import { get, qs } from '../api.js';
import { h, replace, field, select } from '../dom.js';
import { fmtTime, fmtNumber } from '../format.js';

const RANGES = [['1', 'Last 24 hours'], ['7', 'Last 7 days'], ['30', 'Last 30 days']];

/** Fewer alarms than this in the range: the top-10 share says nothing (with 4 alarms it is 100 %). */
export const TOP10_MIN_ALARMS = 50;

/** A verdict badge: within the target or not; `null`: too few alarms to judge. */
function verdict(ok, id) {
  if (ok === null) return h('span', { class: 'badge', dataset: { kpi: id, ok: 'unjudged' }, text: 'TOO FEW ALARMS TO JUDGE' });
  return h('span', { class: `badge ${ok ? 'badge-ok' : 'badge-bad'}`, dataset: { kpi: id, ok: String(ok) }, text: ok ? 'MEETS TARGET' : 'OVER TARGET' });
}

const num = (v, d = 2) => h('td', { class: 'num', text: Number.isFinite(v) ? fmtNumber(v, d) : '—' });

/** The summary table: one row per KPI with measured value, target and verdict. */
function summary(m) {
  const t = m.targets;
  const top10 = m.top.reduce((a, x) => a + x.percent, 0);
  const rows = [
    ['avg-rate', 'Average alarms per operator per 10 min', m.average_per_interval_per_operator,
      `≤ ${t.average_per_interval_per_operator} (at most ${t.average_per_interval_per_operator_max})`,
      m.average_per_interval_per_operator <= t.average_per_interval_per_operator_max],
    ['max-rate', 'Peak alarms per operator in 10 min', m.max_per_interval_per_operator,
      `≤ ${t.max_per_interval_per_operator}`, m.max_per_interval_per_operator <= t.max_per_interval_per_operator],
    ['flood', 'Time in flood (%)', m.percent_time_in_flood, `< ${t.percent_time_in_flood}`, m.percent_time_in_flood < t.percent_time_in_flood],
    ['top10', 'Top 10 alarms\u2019 share of all alarms (%)', top10, `≤ ${t.top10_percent} (judged from ${TOP10_MIN_ALARMS} alarms)`,
      m.total_activations < TOP10_MIN_ALARMS ? null : top10 <= t.top10_percent,
      ` of ${m.total_activations} alarm${m.total_activations === 1 ? '' : 's'}`],
    ['chattering', 'Chattering alarms', m.chattering.length, `${t.chattering}`, m.chattering.length <= t.chattering],
    ['stale', 'Stale alarms (active over 24 h)', m.stale.length, `< ${t.stale}`, m.stale.length < t.stale],
    ['shelved', 'Shelved alarms now', m.shelved.length, `≤ ${t.shelved} (site guideline)`, m.shelved.length <= t.shelved],
  ];
  return h('table', { class: 'data', id: 'kpi-summary' },
    h('thead', {}, h('tr', {}, ['KPI', 'Measured', 'ISA-18.2 target', ''].map((x) => h('th', { scope: 'col', text: x })))),
    h('tbody', {}, rows.map(([id, label, v, target, ok, of = '']) => h('tr', { dataset: { kpi: id } },
      h('th', { scope: 'row', text: label }),
      h('td', { class: 'num', text: `${Number.isFinite(v) ? fmtNumber(v, Number.isInteger(v) ? 0 : 2) : '—'}${of}` }),
      h('td', { text: target }), h('td', {}, verdict(ok, id))))));
}

function section(id, title, body) {
  return h('section', { class: 'card', id, 'aria-labelledby': `${id}-title` }, h('h2', { id: `${id}-title`, text: title }), body);
}

function tableOr(empty, headers, rows, id) {
  if (!rows.length) return h('p', { class: 'hint', id, text: empty });
  return h('div', { class: 'table-wrap', tabindex: '0', role: 'group', 'aria-label': id },
    h('table', { class: 'data', id },
      h('thead', {}, h('tr', {}, headers.map((x) => h('th', { scope: 'col', text: x })))),
      h('tbody', {}, rows)));
}

export default {
  mount(el) {
    const range = select({ id: 'kpi-range' }, RANGES, '1');
    const operators = h('input', { type: 'number', id: 'kpi-operators', min: 1, max: 100, value: 1, size: 4 });
    const out = h('div', { id: 'kpi-out' });
    const form = h('form', { class: 'filters' }, field('Range', range), field('Operator positions', operators),
      h('div', { class: 'btn-row' }, h('button', { type: 'submit', class: 'btn btn-primary', id: 'kpi-refresh', text: 'Refresh' })));
    el.append(h('h1', { class: 'screen-title', text: 'Alarm KPIs' }), h('div', { class: 'card' }, form), out);
    form.addEventListener('submit', (e) => { e.preventDefault(); load(); });
    range.addEventListener('change', load);

    async function load() {
      const to = Date.now();
      const from = to - Number(range.value) * 86_400_000;
      replace(out, h('p', { class: 'loading', text: 'Loading…' }));
      let m;
      try {
        m = await get(`/api/alarms/metrics${qs({ from, to, operators: operators.value || 1 })}`);
      } catch (e) {
        replace(out, h('p', { class: 'error', text: `Cannot load the alarm KPIs: ${e.detail}` }));
        return;
      }
      const floodTotal = m.floods.reduce((a, f) => a + f.count, 0);
      replace(out,
        h('p', { class: 'hint', role: 'status', id: 'kpi-status',
          text: `${m.total_activations} alarm${m.total_activations === 1 ? '' : 's'} from ${fmtTime(m.from)} to ${fmtTime(m.to)}, ${m.operators} operator position${m.operators === 1 ? '' : 's'}.` }),
        section('kpi-targets', 'Against the ISA-18.2 targets', summary(m)),
        section('kpi-positions', 'Alarms per 10 minutes by selection (one operator position each)', tableOr('No alarms in the range.',
          ['Selection', 'Alarms', 'Average per 10 min', 'Peak in 10 min', 'Floods', ''],
          m.positions.map((p) => h('tr', { dataset: { selection: p.selection } }, h('td', { text: p.selection || '(none)' }), num(p.total_activations, 0),
            num(p.average_per_interval), num(p.max_per_interval, 0), num(p.floods, 0),
            h('td', {}, verdict(p.average_per_interval <= m.targets.average_per_interval_per_operator_max && p.max_per_interval <= m.targets.max_per_interval_per_operator, `position-${p.selection}`)))),
          'kpi-positions-table')),
        section('kpi-floods', `Floods (over ${m.targets.max_per_interval_per_operator} alarms per operator in 10 min)`, tableOr('No flood in the range.',
          ['Start', 'End', 'Alarms'], m.floods.map((f) => h('tr', {}, h('td', { text: fmtTime(f.start) }), h('td', { text: fmtTime(f.end) }), num(f.count, 0))),
          'kpi-floods-table')),
        floodTotal ? h('p', { class: 'hint', text: `${floodTotal} alarms came in floods.` }) : '',
        section('kpi-top', 'Top 10 most frequent alarms', tableOr('No alarms in the range.',
          ['Alarm', 'Activations', 'Share (%)'], m.top.map((a) => h('tr', { dataset: { key: a.key } }, h('td', { text: a.key }), num(a.count, 0), num(a.percent, 1))),
          'kpi-top-table')),
        section('kpi-chattering', 'Chattering alarms (3 or more in a minute)', tableOr('No chattering alarm.',
          ['Alarm', 'Activations', 'Most in one minute'], m.chattering.map((a) => h('tr', { dataset: { key: a.key } }, h('td', { text: a.key }), num(a.activations, 0), num(a.max_in_window, 0))),
          'kpi-chattering-table')),
        section('kpi-stale', 'Stale alarms (active over 24 hours)', tableOr('No stale alarm.',
          ['Alarm', 'Active since', 'Hours'], m.stale.map((a) => h('tr', { dataset: { key: a.key } }, h('td', { text: a.key }), h('td', { text: fmtTime(a.active_since) }), num(a.hours, 1))),
          'kpi-stale-table')),
        section('kpi-shelved', 'Shelved alarms', tableOr('No alarm is shelved.',
          ['Alarm', 'Message', 'By', 'Since', 'Until', 'Reason'], m.shelved.map((a) => h('tr', { dataset: { key: a.key } }, h('td', { text: a.key }), h('td', { text: a.message }),
            h('td', { text: a.by ?? '' }), h('td', { text: a.since ? fmtTime(a.since) : '' }), h('td', { text: a.until ? fmtTime(a.until) : '' }), h('td', { text: a.reason ?? '' }))),
          'kpi-shelved-table')));
    }
    load();
  },
};
