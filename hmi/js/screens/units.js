// Per-unit screens: one microgrid unit at a time, with every tag of the unit
// and its power and setpoint over the last hour.

import { get, qs } from '../api.js';
import { h, replace } from '../dom.js';
import { Binder, valueEl } from '../ui.js';
import { TrendChart, PEN_COLORS } from '../components/chart.js';
import { tagList } from './common.js';
import { microgridUnits, stateFormat } from './microgrid.js';

const HOUR = 3_600_000;

export default {
  mount(el, ctx) {
    let binder = null;
    let chart = null;
    let timer = null;
    let disposed = false;
    const tabs = h('div', { class: 'tabs', role: 'group', 'aria-label': 'Units' });
    const body = h('div', {});
    el.append(h('h1', { class: 'screen-title', text: 'Units' }), tabs, body);

    async function show(units, u) {
      if (binder) binder.dispose();
      if (chart) chart.dispose();
      clearInterval(timer);
      binder = new Binder();
      history.replaceState(null, '', `#/units/${u.id}`);
      for (const b of tabs.children) b.setAttribute('aria-pressed', String(b.dataset.unit === u.id));
      const tags = (await tagList()).filter((t) => t.name.startsWith(`${u.prefix}.`));
      const canvas = h('canvas', { id: 'unit-canvas' });
      chart = new TrendChart(canvas);
      const trendTags = [`${u.prefix}.P_kW`, `${u.prefix}.Setpoint_kW`].filter((n) => tags.some((t) => t.name === n));
      replace(body, h('div', { class: 'mg-layout' },
        h('section', { class: 'card', 'aria-label': `${u.id} power` }, h('h2', { text: `${u.label}: power and setpoint, last hour` }),
          h('div', { class: 'trend-canvas-wrap' }, canvas),
          h('p', { class: 'hint' }, trendTags.map((t, i) => {
            const sw = h('span', { class: 'pen-swatch' });
            sw.style.background = PEN_COLORS[i];
            return h('span', { class: 'ratio legend-item' }, sw, t);
          }))),
        h('section', { class: 'card', 'aria-label': `${u.id} values` }, h('h2', { text: u.label }),
          h('table', { class: 'data' }, h('tbody', {}, tags.map((t) => h('tr', {},
            h('th', { scope: 'row', title: t.name, text: t.description || t.name.slice(u.prefix.length + 1) }),
            h('td', { class: 'num' }, valueEl(binder, t.name, { units: t.units, kind: t.kind, format: t.name.endsWith('.State') ? stateFormat(t.description) : undefined })))))))));
      const load = async () => {
        const to = Date.now();
        try {
          const r = await get(`/api/trends${qs({ tags: trendTags.join(','), from: to - HOUR, to, points: 300 })}`);
          if (disposed) return;
          chart.setData(trendTags.map((t, i) => ({ tag: t, color: PEN_COLORS[i], units: 'kW', buckets: ((r.series || []).find((s) => s.tag === t) || { buckets: [] }).buckets })), to - HOUR, to);
        } catch (e) {
          chart.setData([], to - HOUR, to);
        }
      };
      if (trendTags.length && ctx.session.screens.includes('trends')) { load(); timer = setInterval(load, 10_000); }
    }

    (async () => {
      let units;
      try { units = await microgridUnits(); } catch (e) {
        replace(body, h('p', { class: 'error', text: `Cannot list the units: ${e.detail}` }));
        return;
      }
      if (disposed) return;
      const wanted = (location.hash.match(/^#\/units\/([\w.-]+)/) || [])[1];
      replace(tabs, units.map((u) => h('button', { type: 'button', class: 'btn', 'aria-pressed': 'false', dataset: { unit: u.id },
        onclick: () => show(units, u), text: u.label })));
      const first = units.find((u) => u.id === wanted) || units[0];
      if (first) show(units, first); else replace(body, h('p', { class: 'empty', text: 'No microgrid units are configured.' }));
    })();
    return () => { disposed = true; clearInterval(timer); if (binder) binder.dispose(); if (chart) chart.dispose(); };
  },
};
