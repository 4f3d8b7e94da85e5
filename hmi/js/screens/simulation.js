// Simulation panel (training): only in a server that runs simulators
// (`gridscada demo`, replay), for a group given the `simulation` screen.
// A trainer injects and repairs zone faults (permanent, or transient with a
// clearing time), takes devices offline, slows or corrupts their replies,
// and changes zone loads and the plant's input profiles. Every action is
// recorded by the server as a `training` event with the trainer's name.
// The status tables refresh every 2 s; the forms are never redrawn under
// the trainer's hands.

import { get, post, put, del } from '../api.js';
import { h, replace, field, select } from '../dom.js';
import { fmtNumber, fmtTime } from '../format.js';
import { attempt, toast } from '../ui.js';

const POLL_MS = 2000;
const enc = encodeURIComponent;

const INPUTS = [
  ['irradiance', 'Irradiance', 'W/m²', 'irradiance_w_m2'],
  ['wind_speed', 'Wind speed', 'm/s', 'wind_speed_m_s'],
  ['demand', 'Demand', 'kW', 'demand_kw'],
];

function zoneLabel(z) { return z === 0 ? 'Busbar (load 0)' : `Zone ${z}`; }

function profileText(p) {
  if (!p) return '—';
  if (p.kind === 'builtin') return 'built-in';
  if (p.kind === 'scaled') return `built-in × ${p.factor}`;
  if (p.kind === 'constant') return `constant ${p.value}`;
  return 'daily table (scenario)';
}

function faultText(z) {
  if (!z.fault) return 'none';
  if (z.fault === 'permanent') return 'PERMANENT';
  return z.fault_clears_at ? `TRANSIENT until ${fmtTime(z.fault_clears_at)}` : 'TRANSIENT (clears at its trip)';
}

export default {
  mount(el) {
    let timer = null;
    let state = null;
    // Panels by the names the plant gives them (the screens' labels); the id
    // until those arrive, or for a panel without a screen.
    let panelNames = new Map();
    const panelName = (id) => panelNames.get(id) || id;
    get('/api/screens').then(({ screens }) => {
      panelNames = new Map((screens || []).filter((e) => e.kind === 'panel').map((e) => [e.panel || e.id, e.label]));
      if (state) draw(state);
    }).catch(() => { /* the ids stay */ });

    const status = h('p', { class: 'hint', id: 'sim-status', role: 'status' });
    el.append(h('h1', { class: 'screen-title', text: 'Simulation (training)' }),
      h('p', { class: 'hint', text: 'Drills on the simulated plant. Every action here is recorded in the event log as training, with your name.' }),
      status);

    // ----- Zone faults -----
    const fPanel = select({ id: 'sim-fault-panel' }, []);
    const fZone = select({ id: 'sim-fault-zone' }, []);
    const fKind = select({ id: 'sim-fault-kind' }, [['permanent', 'Permanent (until repaired)'], ['transient', 'Transient (clears by itself)']], 'permanent');
    const fClears = h('input', { id: 'sim-fault-clears', type: 'number', min: 1, max: 3600, step: 1, value: '10', disabled: true });
    const fillZones = () => {
      const p = state && state.panels.find((x) => x.id === fPanel.value);
      const current = fZone.value;
      replace(fZone, (p ? [{ zone: 0 }, ...p.zones] : []).map((z) =>
        h('option', { value: z.zone, selected: String(z.zone) === current, text: zoneLabel(z.zone) })));
    };
    fPanel.addEventListener('change', fillZones);
    fKind.addEventListener('change', () => { fClears.disabled = fKind.value !== 'transient'; });
    const faultForm = h('form', { class: 'filters', id: 'sim-fault-form' },
      field('Panel', fPanel), field('Zone', fZone), field('Kind', fKind), field('Clears after (s)', fClears),
      h('div', { class: 'btn-row' }, h('button', { type: 'submit', class: 'btn btn-danger', id: 'sim-inject', text: 'Inject fault' })));
    faultForm.addEventListener('submit', async (e) => {
      e.preventDefault();
      const body = { panel: fPanel.value, zone: Number(fZone.value), kind: fKind.value };
      if (fKind.value === 'transient' && fClears.value) body.clears_after_s = Number(fClears.value);
      const ok = await attempt('Inject fault', () => post('/api/sim/faults', body));
      if (ok) { toast(`Fault injected on ${zoneLabel(body.zone).toLowerCase()} of ${panelName(body.panel)}`); refresh(); }
    });
    const faultBox = h('div', { class: 'table-wrap', tabindex: '0', role: 'group', 'aria-label': 'Zone faults table' });

    // ----- Devices -----
    const devBox = h('div', { class: 'table-wrap', tabindex: '0', role: 'group', 'aria-label': 'Simulated devices table' });
    const dName = select({ id: 'sim-link-device' }, []);
    const dSlow = h('input', { id: 'sim-link-slow', type: 'number', min: 0, max: 60000, step: 100, value: '0' });
    const dReplies = select({ id: 'sim-link-replies' }, [['normal', 'Correct'], ['corrupt', 'Corrupted frames'], ['exception', 'Modbus exception']], 'normal');
    const linkForm = h('form', { class: 'filters', id: 'sim-link-form' },
      field('Device', dName), field('Added latency (ms)', dSlow), field('Replies', dReplies),
      h('div', { class: 'btn-row' }, h('button', { type: 'submit', class: 'btn btn-primary', id: 'sim-link-apply', text: 'Apply' })));
    linkForm.addEventListener('submit', async (e) => {
      e.preventDefault();
      const slow = Number(dSlow.value) || 0;
      const body = { replies: dReplies.value };
      if (slow > 0) body.slow_reply_ms = slow;
      const ok = await attempt('Change the device link', () => put(`/api/sim/devices/${enc(dName.value)}/link`, body));
      if (ok) { toast(`${dName.value}: link changed`); refresh(); }
    });

    // ----- Zone loads -----
    const lPanel = select({ id: 'sim-load-panel' }, []);
    const lZone = h('input', { id: 'sim-load-zone', type: 'number', min: 1, max: 255, step: 1, value: '1' });
    const lKw = h('input', { id: 'sim-load-kw', type: 'number', min: 0, max: 10000, step: 0.1, value: '3' });
    const lPf = h('input', { id: 'sim-load-pf', type: 'number', min: 0.05, max: 1, step: 0.01, value: '0.9' });
    const loadForm = h('form', { class: 'filters', id: 'sim-load-form' },
      field('Panel', lPanel), field('Zone', lZone), field('Load (kW)', lKw), field('Power factor', lPf),
      h('div', { class: 'btn-row' }, h('button', { type: 'submit', class: 'btn btn-primary', id: 'sim-load-apply', text: 'Set load' })));
    loadForm.addEventListener('submit', async (e) => {
      e.preventDefault();
      const ok = await attempt('Set the zone load', () => put(`/api/sim/zones/${enc(lPanel.value)}/${enc(lZone.value)}/load`,
        { kw: Number(lKw.value), pf: Number(lPf.value) }));
      if (ok) { toast(`Load of zone ${lZone.value} of ${panelName(lPanel.value)} set`); refresh(); }
    });

    // ----- Plant inputs -----
    const iName = select({ id: 'sim-input-name' }, INPUTS.map(([id, label]) => [id, label]), 'demand');
    const iKind = select({ id: 'sim-input-kind' }, [['builtin', 'Built-in curve'], ['scaled', 'Built-in × factor'], ['constant', 'Constant value']], 'scaled');
    const iValue = h('input', { id: 'sim-input-value', type: 'number', min: 0, step: 'any', value: '1' });
    const inputForm = h('form', { class: 'filters', id: 'sim-input-form' },
      field('Input', iName), field('Profile', iKind), field('Factor or value', iValue),
      h('div', { class: 'btn-row' }, h('button', { type: 'submit', class: 'btn btn-primary', id: 'sim-input-apply', text: 'Apply profile' })));
    inputForm.addEventListener('submit', async (e) => {
      e.preventDefault();
      const profile = { kind: iKind.value };
      if (iKind.value === 'scaled') profile.factor = Number(iValue.value);
      if (iKind.value === 'constant') profile.value = Number(iValue.value);
      const ok = await attempt('Change the profile', () => put(`/api/sim/inputs/${enc(iName.value)}`, { profile }));
      if (ok) { toast(`${iName.selectedOptions[0].textContent}: ${profileText(profile)}`); refresh(); }
    });
    const inputBox = h('div', { class: 'table-wrap', tabindex: '0', role: 'group', 'aria-label': 'Plant inputs table' });
    const inputCard = h('section', { class: 'card', 'aria-labelledby': 'sim-inputs-title' },
      h('h2', { id: 'sim-inputs-title', text: 'Plant inputs (PV, wind, demand)' }), inputForm, inputBox);

    el.append(
      h('section', { class: 'card', 'aria-labelledby': 'sim-faults-title' }, h('h2', { id: 'sim-faults-title', text: 'Zone faults' }), faultForm, faultBox),
      h('section', { class: 'card', 'aria-labelledby': 'sim-devices-title' }, h('h2', { id: 'sim-devices-title', text: 'Devices' }), linkForm, devBox),
      h('section', { class: 'card', 'aria-labelledby': 'sim-loads-title' }, h('h2', { id: 'sim-loads-title', text: 'Zone loads' }), loadForm),
      inputCard);

    async function repair(panel, zone) {
      const ok = await attempt('Repair', () => del(`/api/sim/faults/${enc(panel)}/${zone}`));
      if (ok !== undefined) { toast(`${zoneLabel(zone)} of ${panelName(panel)} repaired`); refresh(); }
    }

    async function setOffline(device, offline) {
      const ok = await attempt(offline ? 'Take offline' : 'Bring online', () => post(`/api/sim/devices/${enc(device)}/${offline ? 'offline' : 'online'}`));
      if (ok) { toast(`${device} ${offline ? 'offline' : 'online'}`); refresh(); }
    }

    /** Fills a select with [value, text] pairs; the trainer's choice stays. */
    function fillSelect(sel, options) {
      const same = sel.options.length === options.length
        && options.every(([v, t], i) => sel.options[i].value === v && sel.options[i].text === t);
      if (same) return;
      const current = sel.value;
      replace(sel, options.map(([v, t]) => h('option', { value: v, selected: v === current, text: t })));
    }

    function draw(s) {
      state = s;
      const panels = s.panels.map((p) => [p.id, panelName(p.id)]);
      fillSelect(fPanel, panels);
      fillSelect(lPanel, panels);
      if (fZone.options.length === 0) fillZones();
      fillSelect(dName, s.devices.map((d) => [d.name, d.name]));

      const faultRows = s.panels.flatMap((p) => p.zones.map((z) => h('tr', { dataset: { panel: p.id, zone: String(z.zone), faulted: String(!!z.fault) } },
        h('th', { scope: 'row', text: panelName(p.id), title: `panel id ${p.id}` }),
        h('td', { text: p.elcb_closed ? 'closed' : 'TRIPPED' }),
        h('td', { text: zoneLabel(z.zone) }),
        h('td', { class: 'sim-fault' }, z.fault ? h('span', { class: 'badge badge-bad', text: faultText(z) }) : 'none'),
        h('td', { class: 'num', text: `${fmtNumber(z.load_kw, 1)} kW, PF ${fmtNumber(z.pf, 2)}` }),
        h('td', {}, z.fault ? h('button', { type: 'button', class: 'btn btn-small', id: `sim-repair-${p.id}-${z.zone}`, text: 'Repair', onclick: () => repair(p.id, z.zone) }) : '—'))));
      replace(faultBox, h('table', { class: 'data', id: 'sim-faults-table' },
        h('thead', {}, h('tr', {}, ['Panel', 'ELCB', 'Zone', 'Fault', 'Load', 'Action'].map((t) => h('th', { scope: 'col', text: t })))),
        h('tbody', {}, faultRows)));

      replace(devBox, h('table', { class: 'data', id: 'sim-devices-table' },
        h('thead', {}, h('tr', {}, ['Device', 'State', 'Added latency', 'Replies', 'Action'].map((t) => h('th', { scope: 'col', text: t })))),
        h('tbody', {}, s.devices.map((d) => h('tr', { dataset: { device: d.name } },
          h('th', { scope: 'row', text: d.name }),
          h('td', {}, d.offline ? h('span', { class: 'badge badge-bad', text: 'OFFLINE' }) : 'online'),
          h('td', { class: 'num', text: d.slow_reply_ms ? `${d.slow_reply_ms} ms` : '—' }),
          h('td', {}, d.replies === 'normal' ? 'normal' : h('span', { class: 'badge badge-bad', text: d.replies })),
          h('td', {}, h('button', { type: 'button', class: 'btn btn-small', id: `sim-offline-${d.name}`,
            text: d.offline ? 'Bring online' : 'Take offline', onclick: () => setOffline(d.name, !d.offline) })))))));

      inputCard.hidden = !s.inputs;
      if (s.inputs) {
        replace(inputBox, h('table', { class: 'data', id: 'sim-inputs-table' },
          h('thead', {}, h('tr', {}, ['Input', 'Profile', 'Now'].map((t) => h('th', { scope: 'col', text: t })))),
          h('tbody', {}, INPUTS.map(([id, label, unit, now]) => h('tr', { dataset: { input: id } },
            h('th', { scope: 'row', text: label }),
            h('td', { text: profileText(s.inputs[id]) }),
            h('td', { class: 'num', text: `${fmtNumber(s.inputs[now], 1)} ${unit}` }))))));
      }
    }

    async function refresh() {
      try {
        draw(await get('/api/sim/state'));
        status.textContent = '';
        status.className = 'hint';
        el.classList.remove('stale');
      } catch (e) {
        el.classList.add('stale');
        status.textContent = `Not live: ${e.detail}`;
        status.className = 'hint error';
      }
    }
    refresh();
    timer = setInterval(refresh, POLL_MS);
    return () => clearInterval(timer);
  },
};
