// Main screen: single-line diagrams of every substation panel, live.

import { get } from '../api.js';
import { h, replace } from '../dom.js';
import { Binder } from '../ui.js';
import { singleLine } from '../components/singleline.js';
import { devicesUnder, panelPrefix } from './common.js';

export default {
  mount(el, ctx) {
    const binder = new Binder();
    const grid = h('div', { class: 'panel-grid' }, h('p', { class: 'loading', text: 'Loading panels…' }));
    el.append(h('h1', { class: 'screen-title', text: 'Substations' }), grid);
    (async () => {
      try {
        const { panels } = await get('/api/panels');
        const cards = [];
        for (const p of panels) {
          const prefix = panelPrefix(p);
          const devices = await devicesUnder(prefix);
          const open = ctx.session.screens.includes(p.id)
            ? h('a', { class: 'btn btn-small', href: `#/${p.id}`, 'aria-label': `Open the ${p.name} screen`, text: 'Open panel' }) : null;
          cards.push(h('section', { class: 'card panel-card', 'aria-label': p.name, dataset: { panel: p.id } },
            h('div', { class: 'card-head' }, h('h2', { text: p.name }), open),
            singleLine(binder, { prefix, title: p.name, zones: p.zones, devices })));
        }
        replace(grid, cards.length ? cards : h('p', { class: 'empty', text: 'No panels are configured.' }));
      } catch (e) {
        replace(grid, h('p', { class: 'error', text: `Cannot load the panels: ${e.detail}` }));
      }
    })();
    return () => binder.dispose();
  },
};
