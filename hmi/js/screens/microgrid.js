// Microgrid overview: per unit the actual and daily maximum voltage, current
// and power, the efficiency ratio (actual / daily maximum), setpoint and
// state; the demand; and the latest dispatch with its cost and solver.
// Daily maxima come from today's trend (bucket maxima) and then from live values.

import { get, qs, apiUrl } from '../api.js';
import { h, replace } from '../dom.js';
import { decimalsOf, fmtNumber, fmtTime, qualityOf } from '../format.js';
import { Binder, valueEl } from '../ui.js';
import { tagList } from './common.js';

const DISPATCH_POLL_MS = 5000;

/**
 * The microgrid's units as configured (/api/microgrid/units: names, kinds,
 * tag prefixes), with the tags each has; and the demand tag and its load
 * meter's prefix. Nothing here assumes a plant's tag names.
 */
export async function microgridConfig() {
  const tags = await tagList();
  const byName = new Map(tags.map((t) => [t.name, t]));
  const r = await get('/api/microgrid/units');
  const units = (r.units || []).map((c) => ({
    prefix: c.prefix, id: c.id, label: `${c.name} (${c.id})`, kind: c.kind,
    description: (byName.get(`${c.prefix}.P_kW`) || {}).description || '',
    stateDescription: (byName.get(`${c.prefix}.State`) || {}).description || '',
    has: (q) => byName.has(`${c.prefix}.${q}`),
  }));
  return { units, demandTag: r.demand_tag, loadPrefix: r.load_prefix, has: (n) => byName.has(n) };
}

/** The configured units (see microgridConfig). */
export async function microgridUnits() {
  return (await microgridConfig()).units;
}

/**
 * Names the codes of a state tag from its description ("Controller state:
 * 0 off, 1 running, 2 fault"); unknown codes show as the number.
 */
export function stateFormat(description) {
  const labels = new Map();
  const list = String(description).split(':').slice(1).join(':');
  for (const m of list.matchAll(/(\d+)\s+([A-Za-z][A-Za-z _-]*)/g)) labels.set(Number(m[1]), m[2].trim());
  return (v) => {
    const n = Number(v);
    return labels.has(n) ? `${labels.get(n).toUpperCase()} (${n})` : String(v);
  };
}

function startOfToday() {
  const d = new Date();
  d.setHours(0, 0, 0, 0);
  return d.getTime();
}

export default {
  mount(el, ctx) {
    const binder = new Binder();
    let timer = null;
    let disposed = false;
    const unitsBox = h('section', { class: 'card', 'aria-labelledby': 'mg-units' });
    const demandBox = h('section', { class: 'card', 'aria-labelledby': 'mg-demand' });
    const dispatchBox = h('section', { class: 'card', id: 'dispatch', 'aria-labelledby': 'mg-dispatch' },
      h('h2', { id: 'mg-dispatch', text: 'Latest dispatch' }), h('p', { class: 'loading', text: 'Loading…' }));
    el.append(h('h1', { class: 'screen-title', text: 'Microgrid overview' }),
      h('div', { class: 'mg-layout' }, h('div', {}, unitsBox, demandBox), dispatchBox));

    const maxima = new Map(); // tag -> daily max
    const maxEls = new Map(); // tag -> element

    function showMax(tag) {
      const el2 = maxEls.get(tag);
      if (!el2) return;
      const m = maxima.get(tag);
      const u = el2.dataset.units;
      el2.textContent = m === undefined ? '—' : `${fmtNumber(m, decimalsOf(tag))}${u ? ` ${u}` : ''}`;
      el2.title = m === undefined ? 'no value recorded today' : `highest value since ${fmtTime(startOfToday())}`;
    }

    function bump(tag, sample) {
      if (!sample || typeof sample.value !== 'number' || !qualityOf(sample).usable) return;
      const m = maxima.get(tag);
      if (m === undefined || sample.value > m) { maxima.set(tag, sample.value); showMax(tag); }
    }

    (async () => {
      let units;
      let mg;
      try { mg = await microgridConfig(); units = mg.units; } catch (e) {
        replace(unitsBox, h('p', { class: 'error', text: `Cannot list the units: ${e.detail}` }));
        return;
      }
      if (disposed) return;
      // A state of charge column when a unit (a battery) has one.
      const anySoc = units.some((u) => u.has('SoC_pct'));
      // On a phone the detail columns (voltage, current, maxima) give way to P, SoC, setpoint and state.
      const DETAIL = new Set(['V', 'V max today', 'I', 'I max today', 'P max today', 'P / max']);
      const head = ['Unit', 'V', 'V max today', 'I', 'I max today', 'P', 'P max today', 'P / max', anySoc ? 'SoC' : null, 'Setpoint', 'State'].filter(Boolean);
      const rows = units.map((u) => {
        const cells = [h('th', { scope: 'row' }, ctx.session.screens.includes('units')
          ? h('a', { href: `#/units/${u.id}`, text: u.label }) : u.label, )];
        for (const [q, units_] of [['V', 'V'], ['I', 'A'], ['P_kW', 'kW']]) {
          const tag = `${u.prefix}.${q}`;
          const mx = h('span', { class: 'value', dataset: { max: tag, units: units_ } });
          maxEls.set(tag, mx);
          cells.push(h('td', { class: ['num', q !== 'P_kW' && 'col-detail'] }, valueEl(binder, tag, { units: units_ })), h('td', { class: 'num col-detail' }, mx));
          binder.on(tag, (s) => bump(tag, s));
          showMax(tag);
        }
        // Efficiency ratio: actual power over today's maximum.
        const fill = h('span', { class: 'ratio-fill' });
        const pct = h('span', { class: 'value' });
        const ratio = h('span', { class: 'ratio' }, h('span', { class: 'ratio-bar', 'aria-hidden': 'true' }, fill), pct);
        binder.on(`${u.prefix}.P_kW`, (s, connected) => {
          const m = maxima.get(`${u.prefix}.P_kW`);
          const q = qualityOf(s, connected);
          if (!q.usable || typeof s.value !== 'number') {
            pct.textContent = '?'; pct.className = `value ${q.cls}`; pct.title = q.reason || 'no value';
            fill.style.width = '0';
            return;
          }
          if (!m || m <= 0) {
            // A known power, and no output today (a unit that has not run): no ratio to show, and nothing unknown.
            pct.textContent = '—'; pct.className = 'value q-good'; pct.title = 'no output today, so no ratio to today\'s maximum';
            fill.style.width = '0';
            return;
          }
          const r = Math.max(0, s.value / m);
          pct.textContent = `${(r * 100).toFixed(0)} %`; pct.className = 'value q-good'; pct.title = `${fmtNumber(s.value)} / ${fmtNumber(m)} kW`;
          fill.style.width = `${Math.min(100, r * 100)}%`;
        });
        cells.push(h('td', { class: 'col-detail' }, ratio));
        if (anySoc) cells.push(h('td', { class: 'num', dataset: { soc: u.id } }, u.has('SoC_pct') ? valueEl(binder, `${u.prefix}.SoC_pct`, { units: '%' }) : '—'));
        cells.push(
          h('td', { class: 'num' }, u.has('Setpoint_kW') ? valueEl(binder, `${u.prefix}.Setpoint_kW`, { units: 'kW' }) : '—'),
          h('td', { class: 'unit-state' }, u.has('State') ? valueEl(binder, `${u.prefix}.State`, { format: stateFormat(u.stateDescription) }) : '—'));
        // Each cell names its column: on a phone a unit is a card of labelled values.
        cells.forEach((c, i) => { c.dataset.label = head[i]; });
        return h('tr', { dataset: { unit: u.id } }, cells);
      });
      replace(unitsBox, h('h2', { id: 'mg-units', text: 'Units' }),
        h('div', { class: 'table-wrap', tabindex: '0' }, h('table', { class: 'data', id: 'mg-units-table' },
          h('thead', {}, h('tr', {}, head.map((t) => h('th', { scope: 'col', class: DETAIL.has(t) && 'col-detail', text: t })))), h('tbody', {}, rows))));

      // The demand tag, and the load meter's other readings beside it where they exist.
      const load = [['Active power', mg.demandTag, 'kW'],
        ['Reactive power', `${mg.loadPrefix}.Q_kvar`, 'kvar'], ['Voltage', `${mg.loadPrefix}.V`, 'V'], ['Frequency', `${mg.loadPrefix}.Hz`, 'Hz']]
        .filter(([, tag], i) => tag && (i === 0 || mg.has(tag)));
      replace(demandBox, h('h2', { id: 'mg-demand', text: 'Demand' }),
        h('dl', { class: 'kv' }, load.map(([label, tag, u]) => [h('dt', { text: label }),
          h('dd', {}, valueEl(binder, tag, { units: u }))])));

      // Today's maxima from the recorded history (at most 16 pens per request).
      const tags = [...maxEls.keys()];
      for (let i = 0; i < tags.length; i += 16) {
        const part = tags.slice(i, i + 16);
        try {
          const r = await get(`/api/trends${qs({ tags: part.join(','), from: startOfToday(), to: Date.now(), points: 96 })}`);
          for (const s of r.series || []) {
            for (const b of s.buckets) {
              if (b.count && typeof b.max === 'number') {
                const m = maxima.get(s.tag);
                if (m === undefined || b.max > m) maxima.set(s.tag, b.max);
              }
            }
            showMax(s.tag);
          }
        } catch (e) {
          // Without the trends screen the history is not readable: the maxima start from live values.
          for (const t of part) { const m = maxEls.get(t); if (m && maxima.get(t) === undefined) m.title = `history not available: ${e.detail}`; }
        }
      }
      binder.update(null);
    })();

    async function loadDispatch() {
      try {
        const d = await get('/api/dispatch');
        drawDispatch(d);
      } catch (e) {
        replace(dispatchBox, h('h2', { id: 'mg-dispatch', text: 'Latest dispatch' }),
          h('p', { class: 'q-bad', id: 'dispatch-error', text: `? ${e.detail}` }));
      }
    }

    function drawDispatch(d) {
      const sp = Object.entries(d.setpoints_kw || {});
      const optimal = d.mode === 'optimal';
      replace(dispatchBox, h('h2', { id: 'mg-dispatch', text: 'Latest dispatch' }),
        h('dl', { class: 'kv' },
          h('dt', { text: 'At' }), h('dd', { text: fmtTime(d.at) }),
          h('dt', { text: 'Mode' }), h('dd', {}, h('span', { class: ['badge', optimal ? 'badge-ok' : 'badge-warn'], text: String(d.mode || '—').toUpperCase() })),
          h('dt', { text: 'Solver status' }), h('dd', { text: String(d.status ?? '—') }),
          d.reason ? [h('dt', { text: 'Reason' }), h('dd', { text: String(d.reason) })] : null,
          h('dt', { text: 'Cost (objective)' }), h('dd', { text: typeof d.objective === 'number' ? fmtNumber(d.objective, 3) : '—' }),
          h('dt', { text: 'Solve time' }), h('dd', { text: typeof d.solve_ms === 'number' ? `${fmtNumber(d.solve_ms, 1)} ms` : '—' }),
          h('dt', { text: 'Load shed' }), h('dd', { text: typeof d.shed_kw === 'number' ? `${fmtNumber(d.shed_kw)} kW` : '—' }),
          d.run_cmd !== undefined && d.run_cmd !== null ? [h('dt', { text: 'Diesel run command' }), h('dd', { text: typeof d.run_cmd === 'object'
            ? Object.entries(d.run_cmd).map(([id, run]) => `${id}: ${run ? 'RUN' : 'STOP'}`).join(', ') || 'none'
            : String(d.run_cmd) })] : null,
          d.write_failures && (Array.isArray(d.write_failures) ? d.write_failures.length : d.write_failures)
            ? [h('dt', { text: 'Write failures' }), h('dd', { class: 'error', text: Array.isArray(d.write_failures) ? d.write_failures.join('; ') : String(d.write_failures) })] : null),
        h('table', { class: 'data', id: 'dispatch-setpoints' },
          h('thead', {}, h('tr', {}, h('th', { scope: 'col', text: 'Unit' }), h('th', { scope: 'col', class: 'num', text: 'Setpoint' }))),
          h('tbody', {}, sp.map(([u, kw]) => h('tr', {}, h('td', { text: u }), h('td', { class: 'num', text: typeof kw === 'number' ? `${fmtNumber(kw)} kW` : String(kw) }))))),
        d.horizon ? drawPlan(d.horizon) : null,
        // The day's dispatches with their setpoints, as CSV.
        h('p', {}, h('a', { class: 'btn', id: 'dispatch-csv', download: 'dispatch-history.csv', text: 'Download 24 h of dispatches (CSV)',
          href: apiUrl(`/api/dispatch/history.csv${qs({ from: Date.now() - 86_400_000, to: Date.now() + 60_000 })}`) })));
    }

    // The look-ahead plan: forecasts, planned state of charge and diesel per
    // period, and what a stored kWh is worth to the dispatch until the next plan.
    function drawPlan(p) {
      const num = (v, unit, digits = 1) => typeof v === 'number' ? `${fmtNumber(v, digits)}${unit}` : '—';
      const n = Number(p.periods) || 0;
      const periodMin = (Number(p.period_s) || 0) / 60;
      const stores = Object.keys(p.soc_kwh || {});
      const diesels = Object.keys(p.diesel_kw || {});
      const values = Object.entries(p.stored_energy_value_per_kwh || {});
      const ok = p.status === 'optimal';
      const rows = [];
      for (let t = 0; t < n; t++) {
        const mins = t * periodMin;
        rows.push(h('tr', {},
          h('td', { text: `+${Math.floor(mins / 60)}:${String(Math.round(mins % 60)).padStart(2, '0')}` }),
          h('td', { class: 'num', text: num(p.demand_kw?.[t], ' kW') }),
          h('td', { class: 'num', text: num(p.renewable_kw?.[t], ' kW') }),
          stores.map((id) => h('td', { class: 'num', text: num(p.soc_kwh[id]?.[t], ' kWh') })),
          diesels.map((id) => h('td', { class: 'num', text: num(p.diesel_kw[id]?.[t], ' kW') }))));
      }
      return h('section', { id: 'dispatch-plan', 'aria-labelledby': 'mg-plan' },
        h('h3', { id: 'mg-plan', text: `Look-ahead plan (${fmtNumber(n * periodMin / 60, 1)} h)` }),
        h('dl', { class: 'kv' },
          h('dt', { text: 'Planned at' }), h('dd', { text: fmtTime(p.at) }),
          h('dt', { text: 'Status' }), h('dd', {}, h('span', { class: ['badge', ok ? 'badge-ok' : 'badge-warn'], text: String(p.status || '—').toUpperCase() })),
          p.reason ? [h('dt', { text: 'Reason' }), h('dd', { text: String(p.reason) })] : null,
          values.map(([id, v]) => [h('dt', { text: `Value of stored energy (${id})` }), h('dd', { text: `${num(v, '', 3)} per kWh` })])),
        ok && n ? h('table', { class: 'data', id: 'dispatch-plan-table' },
          h('caption', { text: 'Forecast and plan per period' }),
          h('thead', {}, h('tr', {},
            h('th', { scope: 'col', text: 'From now' }),
            h('th', { scope: 'col', class: 'num', text: 'Demand' }),
            h('th', { scope: 'col', class: 'num', text: 'PV + wind' }),
            stores.map((id) => h('th', { scope: 'col', class: 'num', text: `${id} SoC` })),
            diesels.map((id) => h('th', { scope: 'col', class: 'num', text: `${id}` })))),
          h('tbody', {}, rows)) : null);
    }

    loadDispatch();
    timer = setInterval(loadDispatch, DISPATCH_POLL_MS);
    return () => { disposed = true; clearInterval(timer); binder.dispose(); };
  },
};
