// Alarm screen: Online (the alarms active now, live, with acknowledge and
// shelve with a reason, out of service with a reason and an end (supervisors),
// and the summary per area: counts by priority for
// each selection) and History (transitions from the database), each with
// filters. A history row says what happened (its cause: "Activated while
// suppressed", "Acknowledged"...) and the state it left the alarm in; the
// state change only when there was one, never "Suppressed → Suppressed".

import { get, post, del, qs, apiUrl } from '../api.js';
import { h, replace, select, field } from '../dom.js';
import { dateFormat, decimalsOf, fmtTime, fmtValue, parseDateTime, roleAtLeast } from '../format.js';
import { live } from '../live.js';
import { siteChoice } from '../sites.js';
import { attempt, formDialog, toast } from '../ui.js';
import { ALARM_HEADERS, KIND_LABELS, STATE_LABELS, causeLabel, drawAlarmRows, stateChange, filterAlarms, priorityChip, sortAlarms, summarize, summaryTable } from '../components/alarmtable.js';
import { PRIORITY_LEVELS } from '../components/alarmfooter.js';

/** Rows of the online list drawn at a time ("Show more" adds a page). */
const ALARM_PAGE = 500;
const STATES = [['', 'Any state'], ...Object.entries(STATE_LABELS).filter(([k]) => k !== 'normal')];

export default {
  mount(el, ctx) {
    const role = ctx.session.role;
    const canAck = roleAtLeast(role, 'operator');
    const canShelve = roleAtLeast(role, 'supervisor');
    const offs = [];
    // The views are toggle buttons (aria-pressed), one pressed at a time.
    const onlineTab = h('button', { type: 'button', class: 'btn', id: 'alarms-tab-online', 'aria-pressed': 'true', text: 'Online' });
    const historyTab = h('button', { type: 'button', class: 'btn', id: 'alarms-tab-history', 'aria-pressed': 'false', text: 'History' });
    const body = h('div', {});
    el.append(h('h1', { class: 'screen-title', text: 'Alarms' }), h('div', { class: 'tabs', role: 'group', 'aria-label': 'Alarm views' }, onlineTab, historyTab), body);

    let cleanup = () => {};
    const showTab = (which) => {
      cleanup();
      onlineTab.setAttribute('aria-pressed', String(which === 'online'));
      historyTab.setAttribute('aria-pressed', String(which === 'history'));
      replace(body);
      cleanup = which === 'online' ? online() : historyView();
    };
    onlineTab.addEventListener('click', () => showTab('online'));
    historyTab.addEventListener('click', () => showTab('history'));

    function online() {
      const selection = h('input', { id: 'alarms-selection', list: 'alarms-selections', size: 10 });
      const selList = h('datalist', { id: 'alarms-selections' });
      const prio = select({ id: 'alarms-priority' }, PRIORITY_LEVELS, '');
      const state = select({ id: 'alarms-state' }, STATES, '');
      const text = h('input', { id: 'alarms-text', type: 'search', size: 16 });
      const count = h('span', { class: 'alarm-count', role: 'status', id: 'alarms-count' });
      const selected = new Set();
      const tbody = h('tbody');
      const ackSel = canAck ? h('button', { type: 'button', class: 'btn', id: 'alarms-ack-selected', text: 'Acknowledge selected' }) : null;
      // The summary per area: standing alarms by priority for each selection; an area opens its list.
      const summaryBox = h('div', { id: 'alarms-summary' });
      body.append(h('section', { class: 'card summary-card', 'aria-labelledby': 'alarms-summary-title' },
        h('h2', { id: 'alarms-summary-title', text: 'Summary by area' }), summaryBox));
      body.append(h('div', { class: 'card' },
        h('div', { class: 'filters' }, field('Selection', selection), selList, field('Priority', prio), field('State', state), field('Text', text), count,
          h('div', { class: 'btn-row' }, ackSel)),
        h('div', { class: 'table-wrap', tabindex: '0' }, h('table', { class: 'data alarms', id: 'alarms-online' },
          h('thead', {}, h('tr', {}, [h('th', { scope: 'col' }, h('span', { class: 'sr-only', text: 'Select' })), ...ALARM_HEADERS.map((t) => h('th', { scope: 'col', text: t })), h('th', { scope: 'col', text: 'Actions' })])),
          tbody))));
      // Shelved and out-of-service alarms are not annunciated, so not in the
      // live list: they are reviewed (and returned) here.
      const hiddenBody = h('tbody');
      const hiddenCount = h('span', { class: 'hint', id: 'alarms-hidden-count' });
      body.append(h('section', { class: 'card', 'aria-labelledby': 'alarms-hidden-title' },
        h('h2', { id: 'alarms-hidden-title', text: 'Shelved and out of service' }), hiddenCount,
        h('div', { class: 'table-wrap', tabindex: '0' }, h('table', { class: 'data alarms', id: 'alarms-hidden' },
          h('thead', {}, h('tr', {}, [...ALARM_HEADERS.map((t) => h('th', { scope: 'col', text: t })), h('th', { scope: 'col', text: 'Actions' })])),
          hiddenBody))));
      let hiddenTimer = null;
      let gone = false;
      const loadHidden = () => {
        if (hiddenTimer || gone) return;
        // At most once a second, whatever the rate of alarm changes.
        hiddenTimer = setTimeout(async () => {
          hiddenTimer = null;
          try {
            const r = await get(`/api/alarms${qs({ state: 'shelved,out_of_service' })}`);
            if (gone) return;
            hiddenCount.textContent = r.count ? '' : 'None.';
            drawAlarmRows(hiddenBody, sortAlarms(r.alarms), { extra: actions });
          } catch { /* the next change retries */ }
        }, 300);
      };

      const actions = (a) => {
        const out = [];
        if (canAck && !a.acked) out.push(h('button', { type: 'button', class: 'btn btn-small', dataset: { ack: String(a.id) }, onclick: () => ack([a.id]), text: 'Ack' }));
        if (canShelve) {
          out.push(a.shelved
            ? h('button', { type: 'button', class: 'btn btn-small', onclick: () => unshelve(a), text: 'Unshelve' })
            : h('button', { type: 'button', class: 'btn btn-small', dataset: { shelve: String(a.id) }, onclick: () => shelve(a), text: 'Shelve' }));
        }
        if (canShelve) {
          out.push(a.out_of_service
            ? h('button', { type: 'button', class: 'btn btn-small', dataset: { inService: String(a.id) }, onclick: () => inService(a), text: 'Return to service' })
            : h('button', { type: 'button', class: 'btn btn-small', dataset: { outOfService: String(a.id) }, onclick: () => outOfService(a), text: 'Out of service' }));
        }
        if (a.shelved && a.shelved.reason) out.push(h('span', { class: 'hint', text: ` shelved: ${a.shelved.reason}` }));
        if (a.out_of_service) {
          const until = a.out_of_service.until ? ` until ${fmtTime(a.out_of_service.until)}` : '';
          out.push(h('span', { class: 'hint', text: ` out of service${until} by ${a.out_of_service.by}: ${a.out_of_service.reason}` }));
        }
        return out;
      };
      let summaryKey = '';
      // Rows drawn: a page at a time, so a flood of standing alarms stays a usable page.
      let pageRows = ALARM_PAGE;
      const draw = () => {
        const list = live.alarms;
        replace(selList, [...new Set(list.map((a) => a.selection))].sort().map((s) => h('option', { value: s })));
        let shown = filterAlarms(list, { selection: selection.value.trim(), minPriority: Number(prio.value) || 0, text: text.value.trim() });
        if (state.value) shown = shown.filter((a) => a.state === state.value);
        shown = sortAlarms(shown);
        count.textContent = `${shown.length} of ${list.length} alarms`;
        // Redrawn only when a count or the area chosen changed.
        const key = JSON.stringify([summarize(list), selection.value.trim()]);
        if (key !== summaryKey) {
          summaryKey = key;
          replace(summaryBox, summaryTable(list, { id: 'alarms-summary-table', current: selection.value.trim(),
            onPick: (sel) => { selection.value = sel; draw(); } }));
        }
        drawAlarmRows(tbody, shown, { extra: actions, selectable: canAck, selected, limit: pageRows,
          more: (n) => [' below. ', h('button', { type: 'button', class: 'btn btn-small', id: 'alarms-more',
            text: `Show ${Math.min(n, ALARM_PAGE)} more`, onclick: () => { pageRows += ALARM_PAGE; draw(); } })] });
      };
      const refilter = () => { pageRows = ALARM_PAGE; draw(); };
      tbody.addEventListener('change', (e) => {
        if (!e.target.classList.contains('alarm-select')) return;
        const id = Number(e.target.value);
        if (e.target.checked) selected.add(id); else selected.delete(id);
      });
      if (ackSel) ackSel.addEventListener('click', () => { if (selected.size) ack([...selected]); else toast('Select alarms to acknowledge first.', 'info'); });
      for (const i of [selection, text]) i.addEventListener('input', refilter);
      for (const i of [prio, state]) i.addEventListener('change', refilter);

      async function ack(ids) {
        const r = await attempt('Acknowledge', () => post('/api/alarms/ack', { ids }));
        if (r) { ids.forEach((i) => selected.delete(i)); toast(`${r.count} alarm${r.count === 1 ? '' : 's'} acknowledged.`, 'ok'); }
      }
      async function shelve(a) {
        const data = await formDialog(`Shelve: ${a.message}`, (f) => f.append(
          h('label', { class: 'field' }, h('span', { class: 'field-label', text: 'Minutes' }), h('input', { type: 'number', name: 'minutes', min: 1, max: 1440, value: 60, required: true })),
          h('label', { class: 'field' }, h('span', { class: 'field-label', text: 'Reason (required)' }), h('input', { name: 'reason', required: true, minlength: 3, id: 'shelve-reason' }))),
        { submitLabel: 'Shelve' });
        if (!data) return;
        const r = await attempt('Shelve', () => post(`/api/alarms/${a.id}/shelve`, { minutes: Number(data.get('minutes')), reason: String(data.get('reason')) }));
        if (r) { toast(`Shelved until ${fmtTime(r.shelved_until)}.`, 'ok'); loadHidden(); }
      }
      // Out of service (maintenance, a faulty instrument): a reason and an end are required.
      async function outOfService(a) {
        const data = await formDialog(`Out of service: ${a.message}`, (f) => f.append(
          h('label', { class: 'field' }, h('span', { class: 'field-label', text: 'Hours (it returns to service by itself then)' }), h('input', { type: 'number', name: 'hours', min: 1, max: 2160, value: 8, required: true, id: 'oos-hours' })),
          h('label', { class: 'field' }, h('span', { class: 'field-label', text: 'Reason (required)' }), h('input', { name: 'reason', required: true, minlength: 3, id: 'oos-reason' }))),
        { submitLabel: 'Take out of service' });
        if (!data) return;
        const r = await attempt('Out of service', () => post(`/api/alarms/${a.id}/out-of-service`, { hours: Number(data.get('hours')), reason: String(data.get('reason')) }));
        if (r) { toast(`Out of service until ${fmtTime(r.until)}.`, 'ok'); loadHidden(); }
      }
      async function inService(a) {
        const r = await attempt('Return to service', () => del(`/api/alarms/${a.id}/out-of-service`));
        if (r !== undefined) { toast('Returned to service.', 'ok'); loadHidden(); }
      }
      async function unshelve(a) {
        const r = await attempt('Unshelve', () => del(`/api/alarms/${a.id}/shelve`));
        if (r !== undefined) { toast('Unshelved.', 'ok'); loadHidden(); }
      }

      const off1 = live.onAlarms(() => { draw(); loadHidden(); });
      draw();
      loadHidden();
      return () => { gone = true; clearTimeout(hiddenTimer); off1(); };
    }

    function historyView() {
      const now = Date.now();
      // Typed as the plant writes them (`[hmi] date_format`, 24-hour): a datetime-local input follows the browser's locale.
      const when = (id, ms) => h('input', { type: 'text', id, size: 19, value: fmtTime(ms), title: `${dateFormat()} HH:MM[:SS], 24-hour` });
      const from = when('hist-from', now - 86_400_000);
      const to = when('hist-to', now + 60_000);
      const selection = h('input', { id: 'hist-selection', size: 10 });
      const prio = select({ id: 'hist-priority' }, PRIORITY_LEVELS, '');
      const text = h('input', { type: 'search', id: 'hist-text', size: 16 });
      const limit = select({ id: 'hist-limit' }, ['100', '500', '2000'], '500');
      const site = siteChoice('hist-site');
      const out = h('div', { class: 'table-wrap', tabindex: '0' });
      // Every transition the filter selects (no row cap), as CSV.
      const csvLink = h('a', { class: 'btn', id: 'hist-csv', href: '#', download: 'alarm-history.csv', text: 'Download CSV' });
      const form = h('form', { class: 'filters' }, field('From', from), field('To', to), field('Selection', selection), field('Priority', prio),
        field('Text', text), field('Rows', limit), site.el, h('div', { class: 'btn-row' }, h('button', { type: 'submit', class: 'btn btn-primary', id: 'hist-search', text: 'Search' }), csvLink));
      body.append(h('div', { class: 'card' }, form, out));
      const load = async () => {
        replace(out, h('p', { class: 'loading', text: 'Loading…' }));
        try {
          const [start, end] = [from.value.trim(), to.value.trim()].map((v) => (v ? parseDateTime(v) : ''));
          if (start === null || end === null) { replace(out, h('p', { class: 'error', role: 'status', text: `Type the times as ${dateFormat()} HH:MM, 24-hour.` })); return; }
          const filter = {
            from: start, to: end,
            selection: selection.value.trim(), min_priority: prio.value, text: text.value.trim(), site: site.value() };
          csvLink.href = apiUrl(`/api/alarms/history.csv${qs(filter)}`);
          const r = await get(`/api/alarms/history${qs({ ...filter, limit: limit.value })}`);
          const rows = r.transitions || [];
          replace(out, h('p', { class: 'hint', role: 'status', text: `${rows.length} transitions${rows.length >= Number(limit.value) ? ' (limit reached: narrow the filter)' : ''}` }),
            h('table', { class: 'data', id: 'alarms-history' },
              h('thead', {}, h('tr', {}, ['Time', 'Alarm', 'Type', 'Event', 'State', 'Value', 'Limit', 'Prio', 'Selection', 'User', 'Message'].map((t) => h('th', { scope: 'col', text: t })))),
              h('tbody', {}, rows.map((t) => h('tr', { dataset: { cause: t.cause ?? '' } },
                h('td', { class: 'nowrap', text: fmtTime(t.ts) }),
                h('td', { text: t.tag || t.alarm_key }),
                h('td', { text: KIND_LABELS[t.kind] || t.kind }),
                // Rows recorded before causes were kept: the change, or that it is not known.
                h('td', { class: ['hist-cause', t.cause ? null : 'hint'], text: causeLabel(t) || (t.from_state === t.to_state ? 'Not recorded' : '') }),
                h('td', { class: 'hist-state', text: stateChange(t) }),
                h('td', { class: 'num', title: 'The value at this transition', text: fmtValue(t.value, decimalsOf(t.tag)) }),
                h('td', { class: 'num', text: fmtValue(t.limit, decimalsOf(t.tag)) }),
                h('td', { class: 'num' }, t.priority === null || t.priority === undefined ? '' : priorityChip(t.priority)),
                h('td', { text: t.selection ?? '' }),
                h('td', { text: t.user ?? '' }),
                h('td', { class: 'hist-message', text: t.message ?? '' }))))));
        } catch (e) {
          replace(out, h('p', { class: 'error', text: `Cannot load the alarm history: ${e.detail}` }));
        }
      };
      form.addEventListener('submit', (e) => { e.preventDefault(); load(); });
      load();
      return () => {};
    }

    showTab('online');
    return () => { cleanup(); offs.forEach((f) => f()); };
  },
};
