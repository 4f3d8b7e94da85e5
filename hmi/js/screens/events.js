// Event screen: operator and system events, filtered by date (or Today),
// type, user and text; the filtered log downloads as CSV.

import { get, qs, apiUrl } from '../api.js';
import { h, replace, field } from '../dom.js';
import { dateFormat, fmtDate, fmtTime, parseDateTime } from '../format.js';
import { dateInput } from '../ui.js';
import { siteChoice } from '../sites.js';

const KNOWN_TYPES = ['login', 'logout', 'login_failed', 'command', 'command_refused', 'mode', 'reset', 'write', 'write_refused', 'write_failed',
  'ack', 'shelve', 'unshelve', 'sequence', 'dispatch', 'simulation', 'training', 'user', 'system'];

export default {
  mount(el) {
    const today = new Date();
    // Typed in the plant's date order (`[hmi] date_format`).
    const from = dateInput({ id: 'events-from' }, today);
    const to = dateInput({ id: 'events-to' }, today);
    const type = h('input', { id: 'events-type', list: 'events-types', size: 14 });
    const types = h('datalist', { id: 'events-types' }, KNOWN_TYPES.map((t) => h('option', { value: t })));
    const user = h('input', { id: 'events-user', size: 12 });
    const text = h('input', { type: 'search', id: 'events-text', size: 16 });
    const site = siteChoice('events-site');
    const out = h('div', { class: 'table-wrap', tabindex: '0' });
    // Every event the filter selects (no row cap), as CSV.
    const csvLink = h('a', { class: 'btn', id: 'events-csv', href: '#', download: 'events.csv', text: 'Download CSV' });
    let todayMode = true;
    const form = h('form', { class: 'filters' },
      field('From date', from), field('To date', to), field('Type', type), types, field('User', user), field('Text', text), site.el,
      h('div', { class: 'btn-row' },
        h('button', { type: 'submit', class: 'btn btn-primary', id: 'events-search', text: 'Search' }),
        h('button', { type: 'button', class: 'btn', id: 'events-today', text: 'Today', onclick: () => { todayMode = true; const d = fmtDate(new Date()); from.value = d; to.value = d; load(); } }),
        csvLink));
    el.append(h('h1', { class: 'screen-title', text: 'Events' }), h('div', { class: 'card' }, form, out));
    form.addEventListener('submit', (e) => { e.preventDefault(); todayMode = false; load(); });

    async function load() {
      const params = { type: type.value.trim(), user: user.value.trim(), text: text.value.trim(), site: site.value() };
      if (todayMode) {
        params.today = true;
        params.tz_offset_min = -new Date().getTimezoneOffset();
      } else {
        const [start, end] = [from.value.trim(), to.value.trim()].map((v) => (v ? parseDateTime(v) : undefined));
        if (start === null || end === null) { replace(out, h('p', { class: 'error', role: 'status', text: `Type the dates as ${dateFormat()}.` })); return; }
        if (start !== undefined) params.from = start;
        if (end !== undefined) params.to = end + 86_400_000 - 1;
      }
      csvLink.href = apiUrl(`/api/events.csv${qs(params)}`);
      params.limit = 1000;
      replace(out, h('p', { class: 'loading', text: 'Loading…' }));
      try {
        const r = await get(`/api/events${qs(params)}`);
        const rows = r.events || [];
        replace(out, h('p', { class: 'hint', role: 'status', id: 'events-count', text: `${rows.length} events${todayMode ? ' today' : ''}` }),
          h('table', { class: 'data', id: 'events-table' },
            h('thead', {}, h('tr', {}, ['Time', 'User', 'Source', 'Type', 'Message'].map((t) => h('th', { scope: 'col', text: t })))),
            h('tbody', {}, rows.map((e) => h('tr', {},
              h('td', { class: 'nowrap', text: fmtTime(e.ts) }), h('td', { text: e.user ?? '' }), h('td', { text: e.source ?? '' }),
              h('td', { text: e.kind ?? '' }), h('td', { text: e.message ?? '' }))))));
      } catch (e) {
        replace(out, h('p', { class: 'error', text: `Cannot load events: ${e.detail}` }));
      }
    }
    load();
  },
};
