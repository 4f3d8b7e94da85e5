// Devices: the communication state of every configured field device and of
// every connection or serial port, refreshed every second, for the engineer
// bringing a plant's devices up and for the operator when the comm light is red.

import { get } from '../api.js';
import { h, replace } from '../dom.js';
import { fmtNumber } from '../format.js';

const POLL_MS = 1000;

function state(d) {
  if (d.connected) return h('span', { class: 'badge badge-ok', text: 'COMM OK' });
  if (d.backing_off) return h('span', { class: 'badge badge-bad', title: 'No answer: the device is probed at growing intervals until it answers again', text: 'LOST, PROBING' });
  return h('span', { class: 'badge badge-bad', text: 'LOST' });
}

const num = (v, digits = 0) => h('td', { class: 'num', text: Number.isFinite(v) ? fmtNumber(v, digits) : '—' });

export default {
  mount(el) {
    const summary = h('p', { class: 'hint', id: 'devices-summary', role: 'status' });
    // Scrolling tables are reachable from the keyboard.
    const devBox = h('div', { class: 'table-wrap', tabindex: '0', role: 'group', 'aria-label': 'Devices table' });
    const linkBox = h('div', { class: 'table-wrap', tabindex: '0', role: 'group', 'aria-label': 'Connections table' });
    const teleBox = h('div', { class: 'table-wrap', tabindex: '0', role: 'group', 'aria-label': 'Telecontrol stations table' });
    const teleCard = h('section', { class: 'card', 'aria-labelledby': 'tele-title', hidden: true },
      h('h2', { id: 'tele-title', text: 'Telecontrol stations' }), teleBox);
    el.append(h('h1', { class: 'screen-title', text: 'Devices' }), summary,
      h('section', { class: 'card', 'aria-labelledby': 'devices-title' }, h('h2', { id: 'devices-title', text: 'Devices' }), devBox),
      teleCard,
      h('section', { class: 'card', 'aria-labelledby': 'links-title' }, h('h2', { id: 'links-title', text: 'Connections and serial ports' }), linkBox));
    let timer = null;

    function draw(view) {
      const lost = view.devices.filter((d) => !d.connected);
      summary.textContent = lost.length
        ? `${lost.length} of ${view.devices.length} devices not answering: ${lost.map((d) => d.name).join(', ')}.`
        : `All ${view.devices.length} devices answer.`;
      summary.className = lost.length ? 'hint error' : 'hint';
      replace(devBox, h('table', { class: 'data', id: 'devices-table' },
        h('thead', {}, h('tr', {}, ['Device', 'State', 'Protocol', 'Address', 'Unit', 'Scan (ms)', 'Scans/s', 'Response (ms)',
          'Requests', 'Errors', 'Timeouts', 'Exceptions', 'Writes', 'Late scans', 'Overruns', 'Last error']
          .map((t) => h('th', { scope: 'col', class: /Scan|Resp|Req|Err|Time|Exc|Wri|Late|Over/.test(t) ? 'num' : '', text: t })))),
        h('tbody', {}, view.devices.map((d) => h('tr', { dataset: { device: d.name, connected: String(d.connected) }, class: d.connected ? '' : 'row-bad' },
          h('th', { scope: 'row', title: d.description, text: d.name }),
          h('td', {}, state(d)),
          h('td', { text: d.protocol.toUpperCase() }),
          h('td', { class: 'nowrap', text: d.address }),
          num(d.unit_id), num(d.scan_ms), num(d.achieved_scans_per_s, 1), num(d.response_ms, 1),
          num(d.requests), num(d.errors), num(d.timeouts), num(d.exceptions), num(d.writes), num(d.late_scans), num(d.overruns),
          h('td', { class: 'last-error', text: d.last_error || '—' }))))));
      const stations = view.devices.filter((d) => d.telecontrol);
      teleCard.hidden = stations.length === 0;
      replace(teleBox, h('table', { class: 'data', id: 'telecontrol-table' },
        h('thead', {}, h('tr', {}, ['Station', 'Link', 'Interrogated (s ago)', 'Interrogations', 'Events', 'Commands', 'Failed', 'Clock offset (ms)', 'Overflows']
          .map((t) => h('th', { scope: 'col', text: t })))),
        h('tbody', {}, stations.map((d) => h('tr', { dataset: { station: d.name } },
          h('th', { scope: 'row', text: d.name }),
          h('td', {}, h('span', { class: `badge ${d.telecontrol.state === 'started' ? 'badge-ok' : 'badge-bad'}`, text: d.telecontrol.state.toUpperCase() })),
          num(d.telecontrol.interrogation_age_s ?? NaN), num(d.telecontrol.interrogations), num(d.telecontrol.events),
          num(d.telecontrol.commands), num(d.telecontrol.commands_failed), num(d.telecontrol.clock_offset_ms ?? NaN),
          num(d.telecontrol.overflows))))));
      replace(linkBox, h('table', { class: 'data', id: 'links-table' },
        h('thead', {}, h('tr', {}, ['Connection', 'State', 'Devices', 'Connects', 'Disconnects', 'Late replies', 'Noise bytes', 'Last error']
          .map((t) => h('th', { scope: 'col', text: t })))),
        h('tbody', {}, view.links.map((l) => h('tr', { dataset: { link: l.link } },
          h('th', { scope: 'row', text: l.link }),
          h('td', {}, l.connected ? h('span', { class: 'badge badge-ok', text: 'OK' }) : h('span', { class: 'badge badge-bad', text: 'DEVICE LOST' })),
          h('td', { text: l.devices.join(', ') }),
          num(l.connects), num(l.disconnects), num(l.late_replies), num(l.garbage_bytes),
          h('td', { text: l.last_error || '—' }))))));
    }

    async function refresh() {
      try {
        draw(await get('/api/devices'));
        el.classList.remove('stale');
      } catch (e) {
        el.classList.add('stale');
        summary.textContent = `Not live: ${e.detail}`;
        summary.className = 'hint error';
      }
    }
    refresh();
    timer = setInterval(refresh, POLL_MS);
    return () => clearInterval(timer);
  },
};
