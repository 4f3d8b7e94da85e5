// Main screen: single-line diagrams of every substation panel, live, with
// each panel's mode (manual mode turns automatic isolation off) and the
// zones its sequence isolated as faulty.

import { get } from '../api.js';
import { h, replace } from '../dom.js';
import { Binder } from '../ui.js';
import { singleLine } from '../components/singleline.js';
import { configuredTags, devicesUnder, panelPrefix } from './common.js';

const POLL_MS = 2000;

/** A panel's mode badge: shown only in manual mode. */
export function modeBadge(id) {
  return h('span', { class: 'badge badge-warn mode-badge', dataset: { modeOf: id }, hidden: true, text: 'MANUAL', title: 'Manual mode: automatic fault isolation is off' });
}

/** Shows a panel's status on its badge and diagram. */
export function showPanelStatus(badge, diagram, p) {
  const manual = p.mode === 'manual';
  badge.hidden = !manual;
  if (diagram) diagram.panelStatus(p);
}

export default {
  mount(el, ctx) {
    const binder = new Binder();
    const grid = h('div', { class: 'panel-grid' }, h('p', { class: 'loading', text: 'Loading panels…' }));
    el.append(h('h1', { class: 'screen-title', text: 'Substations' }), grid);
    const shown = new Map(); // id -> {badge, diagram}
    let timer = null;
    let disposed = false;
    async function refresh() {
      try {
        const { panels } = await get('/api/panels');
        for (const p of panels) { const c = shown.get(p.id); if (c) showPanelStatus(c.badge, c.diagram, p); }
        grid.classList.remove('stale');
      } catch {
        grid.classList.add('stale');
      }
    }
    (async () => {
      try {
        const { panels } = await get('/api/panels');
        const configured = await configuredTags();
        const cards = [];
        for (const p of panels) {
          const prefix = panelPrefix(p);
          const devices = await devicesUnder(prefix);
          const open = ctx.session.screens.includes(p.id)
            ? h('a', { class: 'btn btn-small', href: `#/${p.id}`, 'aria-label': `Open panel: ${p.name}`, text: 'Open panel' }) : null;
          const badge = modeBadge(p.id);
          const diagram = singleLine(binder, { prefix, title: p.name, zones: p.zones, devices, configured });
          shown.set(p.id, { badge, diagram });
          showPanelStatus(badge, diagram, p);
          // A panel of many zones takes the whole row, so its labels keep their size.
          cards.push(h('section', { class: ['card', 'panel-card', p.zones > 6 && 'panel-card-wide'], 'aria-label': p.name, dataset: { panel: p.id } },
            h('div', { class: 'card-head' }, h('h2', {}, p.name, badge), open),
            diagram));
        }
        if (disposed) return;
        replace(grid, cards.length ? cards : h('p', { class: 'empty', text: 'No panels are configured.' }));
        timer = setInterval(refresh, POLL_MS);
      } catch (e) {
        replace(grid, h('p', { class: 'error', text: `Cannot load the panels: ${e.detail}` }));
      }
    })();
    return () => { disposed = true; clearInterval(timer); binder.dispose(); };
  },
};
