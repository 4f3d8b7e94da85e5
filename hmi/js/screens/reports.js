// Reports screen (Supervisors and up): the daily and monthly reports kept in
// the server's data folder, newest first, each opened (HTML, printable) or
// downloaded (HTML, CSV, JSON); and a report made now for a chosen UTC day
// or month.

import { get, post, apiUrl, enc } from '../api.js';
import { h, replace, field, select, table } from '../dom.js';
import { dateFormat, fmtTime, pad, parseDate } from '../format.js';
import { dateInput } from '../ui.js';

const utcDay = (d) => `${d.getUTCFullYear()}-${pad(d.getUTCMonth() + 1)}-${pad(d.getUTCDate())}`;

export default {
  mount(el) {
    const yesterday = new Date(Date.now() - 86_400_000);
    const kind = select({ id: 'reports-kind' }, [['day', 'Day'], ['month', 'Month']], 'day');
    // The UTC day typed in the plant's date order (a date input follows the browser's locale).
    const day = dateInput({ id: 'reports-day', required: true },
      new Date(yesterday.getUTCFullYear(), yesterday.getUTCMonth(), yesterday.getUTCDate()));
    const month = h('input', { type: 'month', id: 'reports-month', value: utcDay(yesterday).slice(0, 7), hidden: true });
    const status = h('p', { class: 'hint', role: 'status', id: 'reports-status' });
    const make = h('button', { type: 'submit', class: 'btn btn-primary', id: 'reports-make', text: 'Make report' });
    const form = h('form', { class: 'filters' },
      field('Period', kind), field('Day (UTC)', day), field('Month (UTC)', month),
      h('div', { class: 'btn-row' }, make));
    const sync = () => {
      const m = kind.value === 'month';
      day.hidden = m;
      day.closest('label').hidden = m;
      month.hidden = !m;
      month.closest('label').hidden = !m;
    };
    kind.addEventListener('change', sync);
    const out = h('div', { class: 'table-wrap', tabindex: '0' });
    el.append(h('h1', { class: 'screen-title', text: 'Reports' }),
      h('div', { class: 'card' }, form, status),
      h('div', { class: 'card' }, out));
    sync();

    form.addEventListener('submit', async (e) => {
      e.preventDefault();
      const period = kind.value === 'month' ? month.value : parseDate(day.value);
      if (!period) {
        if (kind.value === 'day') replace(status, h('span', { class: 'error', text: `Type the day as ${dateFormat()}.` }));
        return;
      }
      make.disabled = true;
      replace(status, `Making the report of ${period}…`);
      try {
        const r = await post('/api/reports', { period });
        replace(status, `Report ${r.id} made.`);
        await load();
      } catch (err) {
        replace(status, h('span', { class: 'error', text: `Cannot make the report: ${err.detail}` }));
      } finally {
        make.disabled = false;
      }
    });

    const link = (id, format, download, text) => h('a', {
      href: apiUrl(`/api/reports/${enc(id)}/${format}${download ? '?download=1' : ''}`),
      target: download ? null : '_blank',
      rel: 'noopener',
      class: 'btn btn-small',
      text,
    });

    async function load() {
      try {
        const r = await get('/api/reports');
        const rows = r.reports || [];
        if (!rows.length) {
          replace(out, h('p', { class: 'hint', id: 'reports-empty', text: 'No report yet: they are made after each day and month, or here on demand.' }));
          return;
        }
        replace(out, table(['Period', 'Kind', 'Made', 'Open', 'Download'], rows.map((x) => [
          x.id,
          x.kind === 'month' ? 'Monthly' : 'Daily',
          fmtTime(x.modified),
          link(x.id, 'html', false, 'Open'),
          h('span', { class: 'btn-row' }, x.formats.map((f) => link(x.id, f, true, f.toUpperCase()))),
        ]), { id: 'reports-table' }));
      } catch (err) {
        replace(out, h('p', { class: 'error', text: `Cannot list reports: ${err.detail}` }));
      }
    }
    load();
  },
};
