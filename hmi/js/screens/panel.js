// Panel screens (one per configured panel): breakers with manual commands, the mode, the
// fault-isolation sequence (step, count_L_cur_c, count_L_cur_sv, isolated
// zones), Reset, and the power analyzer readings.

import { get, post, enc } from '../api.js';
import { h, replace, table } from '../dom.js';
import { fmtDuration, qualityOf, roleAtLeast } from '../format.js';
import { Binder, attempt, confirmDialog, formDialog, toast, valueEl } from '../ui.js';
import { breakerState, singleLine } from '../components/singleline.js';
import { live } from '../live.js';
import { configuredTags, devicesUnder, panelPrefix } from './common.js';

const POLL_MS = 1000;

const ANALYZER = [
  ['Voltage L1', 'V_L1', 'V'], ['Voltage L2', 'V_L2', 'V'], ['Voltage L3', 'V_L3', 'V'],
  ['Current L1', 'I_L1', 'A'], ['Current L2', 'I_L2', 'A'], ['Current L3', 'I_L3', 'A'],
  ['Active power', 'P_kW', 'kW'], ['Reactive power', 'Q_kvar', 'kvar'], ['Power factor', 'PF', ''],
  ['Frequency', 'Hz', 'Hz'], ['Energy', 'kWh', 'kWh'],
];

/** A step of the sequence in plain words; `c` is the load being switched (count_L_cur_c). */
export function stepWords(code, c) {
  const load = Number(c) === 0 ? 'the busbar (load 0, MCCB)' : `zone ${c}`;
  switch (code) {
    case 'idle': return 'Idle: watching for a trip';
    case 'tripped': return 'ELCB tripped: opening the MCCB and every zone';
    case 'reclose_wait': return 'Waiting to reclose the ELCB';
    case 'elcb_reset': return 'Resetting the ELCB';
    case 'oluc': return `Testing ${load}: closing it`;
    case 'oluc_dwell': return `Testing ${load}: waiting to see it hold`;
    case 'oldc': return 'Closing the remaining healthy zones';
    case 'oldc_dwell': return 'Closing the remaining healthy zones: waiting to see each hold';
    case 'isolated': return 'Done: faulty zones isolated, the others restored';
    case 'lockout': return 'Locked out: too many trips; repair, then Reset';
    case 'suspended': return 'Suspended: signals with Bad quality';
    case 'manual': return 'Manual mode: the sequence does not act';
    default: return code ? String(code) : '—';
  }
}

/** The zones (and busbar) the sequence isolated as faulty, in words. */
export function isolatedZones(status) {
  if (!status) return [];
  const out = (status.faulty_zones || []).map((z) => `Zone ${z}`);
  if (status.load0_faulty) out.unshift('the busbar (load 0)');
  return out;
}

/**
 * The last sequence in words: nothing before the first fault, "running" during one.
 * `restore_s` is null when the sequence did not restore (lockout, stopped): no time is shown then.
 */
export function lastSequence(status) {
  const ls = (status && status.last_sequence) || {};
  const outcome = String(ls.outcome || 'none').toLowerCase();
  if (outcome === 'none') return 'none since start';
  if (outcome === 'running') return 'a sequence is running now';
  // A Reset with nothing tripped "restores" in no time: not a sequence worth reporting.
  if (outcome === 'restored' && !Number(ls.trips) && !Number(ls.switching_ops)) return 'no fault since start or the last Reset';
  const restoreS = typeof ls.restore_s === 'number' && Number.isFinite(ls.restore_s) ? ls.restore_s : null;
  const took = restoreS === null ? '' : ` in ${fmtDuration(restoreS)}`;
  const parts = [{
    restored: `every zone restored${took}`,
    isolated: `faulty zones isolated, healthy zones restored${took}`,
    lockout: 'lockout: the sequence gave up without restoring',
    stopped: 'stopped by the operator (manual mode) before restoring',
  }[outcome] || outcome];
  parts.push(`${ls.switching_ops} switching ops`, `${ls.trips} trips`, `${ls.elcb_resets} ELCB resets`);
  return parts.join(', ');
}

/** How the last sequence was resumed after a restart or a failover ("" if it was not). */
export function resumedSequence(status) {
  return (status && typeof status.resumed === 'string') ? status.resumed : '';
}

const breakerLabel = (name) => (name === 'elcb' ? 'ELCB' : name === 'mccb' ? 'MCCB' : name.replace(/^zone(\d+)$/, 'Zone $1'));

export function panelScreen(id) {
  return {
    mount(el, ctx) {
      const role = ctx.session.role;
      const canOperate = roleAtLeast(role, 'operator');
      const canMode = roleAtLeast(role, 'supervisor');
      const binder = new Binder();
      let status = null;
      let diagram = null;
      let prefix = null;
      let timer = null;
      let disposed = false;

      const title = h('h1', { class: 'screen-title', text: `Panel ${id}` });
      // On a phone the cards stack as an operator needs them: diagram, sequence, breakers, analyzer.
      const diagramBox = h('section', { class: 'card pn-diagram', 'aria-label': 'Single-line diagram' });
      const seqBox = h('section', { class: 'card seq-card pn-sequence', 'aria-labelledby': `seq-${id}` });
      const breakersBox = h('section', { class: 'card pn-breakers', 'aria-labelledby': `bk-${id}` });
      const paBox = h('section', { class: 'card pn-analyzer', 'aria-labelledby': `pa-${id}` });
      el.append(title, h('div', { class: 'panel-layout' },
        h('div', { class: 'panel-left' }, diagramBox, paBox),
        h('div', { class: 'panel-right' }, seqBox, breakersBox)));
      if (!canOperate) el.insertBefore(h('p', { class: 'note', text: `View only: your role (${role}) may not operate this panel.` }), el.children[1]);

      // Sequence and mode, from the panel's status.
      const f = {};
      const dd = (k) => (f[k] = h('dd', { id: `${id}-${k}` }));
      const modeBtns = canMode ? h('div', { class: 'btn-row' },
        h('button', { type: 'button', class: 'btn', id: `${id}-mode-auto`, onclick: () => setMode('auto'), text: 'Auto' }),
        h('button', { type: 'button', class: 'btn', id: `${id}-mode-manual`, onclick: () => setMode('manual'), text: 'Manual' })) : null;
      const resetBtn = canOperate ? h('button', { type: 'button', class: 'btn btn-primary', id: `${id}-reset`, onclick: reset, text: 'Reset' }) : null;
      replace(seqBox,
        h('h2', { id: `seq-${id}`, text: 'Fault isolation' }),
        h('dl', { class: 'kv' },
          h('dt', { text: 'Mode' }), dd('mode'),
          h('dt', { text: 'Step' }), dd('step'),
          h('dt', { text: 'Load being switched', title: 'count_L_cur_c' }), dd('count_c'),
          h('dt', { text: 'Saved faulty load', title: 'count_L_cur_sv' }), dd('count_sv'),
          h('dt', { text: 'Isolated zones' }), dd('faulty'),
          h('dt', { text: 'Lockout' }), dd('lockout'),
          h('dt', { text: 'Communication' }), dd('comm'),
          h('dt', { text: 'Last sequence' }), dd('last'),
          h('dt', { text: 'Resumed' }), dd('resumed')),
        modeBtns, resetBtn);

      // Breakers: state and commands.
      const bkBody = h('tbody');
      replace(breakersBox, h('h2', { id: `bk-${id}`, text: 'Breakers' }),
        h('p', { class: 'hint', id: `${id}-bk-hint` }),
        h('table', { class: 'data breakers' },
          h('thead', {}, h('tr', {}, ['Breaker', 'State', canOperate ? 'Command' : null].filter(Boolean).map((t) => h('th', { scope: 'col', text: t })))),
          bkBody));

      async function refresh() {
        try {
          status = await get(`/api/panels/${enc(id)}`);
          seqBox.classList.remove('stale');
          seqBox.title = '';
          draw();
        } catch (e) {
          // Keep the last status on view, greyed, with the reason.
          seqBox.classList.add('stale');
          seqBox.title = `not live: ${e.detail}`;
          if (f.comm) f.comm.textContent = `? ${e.detail}`;
        }
      }

      function draw() {
        if (!status) return;
        const manual = status.mode === 'manual';
        f.mode.textContent = manual ? 'MANUAL' : 'AUTO';
        f.mode.className = manual ? 'badge badge-warn' : 'badge badge-ok';
        drawSeq();
        const faulty = (status.faulty_zones || []).map((z) => `Zone ${z}`);
        if (status.load0_faulty) faulty.unshift('Busbar (load 0)');
        f.faulty.textContent = faulty.length ? faulty.join(', ') : 'none';
        f.faulty.className = faulty.length ? 'badge badge-bad' : '';
        f.lockout.textContent = status.lockout ? 'LOCKED OUT' : 'no';
        f.lockout.className = status.lockout ? 'badge badge-bad' : '';
        f.comm.textContent = status.comm_ok ? 'all signals Good' : 'signals with Bad quality';
        f.comm.className = status.comm_ok ? '' : 'badge badge-bad';
        f.last.textContent = lastSequence(status);
        f.resumed.textContent = resumedSequence(status) || 'no';
        if (diagram) diagram.panelStatus(status);
        if (modeBtns) {
          modeBtns.children[0].setAttribute('aria-pressed', String(!manual));
          modeBtns.children[1].setAttribute('aria-pressed', String(manual));
        }
        const hint = document.getElementById(`${id}-bk-hint`);
        // Only a supervisor (or above) switches the mode: an operator is told who can.
        const toManual = canMode ? 'Switch to Manual (above) to operate them.' : 'A supervisor can switch the panel to Manual; then you can operate them.';
        if (hint) hint.textContent = canOperate ? (manual ? 'Manual mode: breakers may be operated.' : `Auto mode: the sequence operates the breakers. ${toManual}`) : '';
        for (const b of bkBody.querySelectorAll('button[data-breaker]')) b.disabled = !manual;
      }

      // The step and counters, pushed live from the derived tags {prefix}.Seq.*
      // (every step is seen), else from the polled status.
      function liveSeq(k) {
        if (!prefix) return undefined;
        const smp = binder.sample(`${prefix}.Seq.${k}`);
        return smp && qualityOf(smp, live.connected).usable ? smp.value : undefined;
      }
      let lastPushed;
      function drawSeq() {
        if (!status) return;
        const pushed = liveSeq('Step');
        // A new step pushed live: fetch the rest of the status (outcome, isolated zones) at once.
        if (pushed !== undefined && lastPushed !== undefined && pushed !== lastPushed) refresh();
        lastPushed = pushed;
        const code = pushed ?? status.step;
        const c = liveSeq('count_L_cur_c') ?? status.count_L_cur_c;
        const sv = liveSeq('count_L_cur_sv') ?? status.count_L_cur_sv;
        f.step.textContent = stepWords(code, c);
        f.step.title = `step ${code}, count_L_cur_c ${c}, count_L_cur_sv ${sv}`;
        f.step.dataset.step = String(code);
        f.count_c.textContent = String(c);
        f.count_sv.textContent = String(sv);
      }

      function drawBreakerRows(prefix, names) {
        replace(bkBody, names.map((name) => {
          const st = h('span', { class: 'bk-text' });
          const closedTag = name === 'elcb' ? `${prefix}.ELCB.Closed` : name === 'mccb' ? `${prefix}.MCCB.Closed` : `${prefix}.Zone${name.slice(4)}.Closed`;
          const cmdTag = name === 'elcb' ? null : name === 'mccb' ? `${prefix}.MCCB.Cmd` : `${prefix}.Zone${name.slice(4)}.Cmd`;
          const drawSt = (_s, connected) => {
            const b = breakerState(binder.sample(closedTag), cmdTag ? binder.sample(cmdTag) : null, connected, name === 'elcb');
            st.textContent = b.label === 'UNKNOWN' ? '? UNKNOWN' : b.label;
            st.className = `bk-text ${b.cls}`;
            st.title = b.reason;
          };
          binder.on(closedTag, drawSt);
          if (cmdTag) binder.on(cmdTag, drawSt);
          const cells = [h('th', { scope: 'row', text: breakerLabel(name) }), h('td', {}, st)];
          if (canOperate) {
            cells.push(h('td', { class: 'actions' },
              h('button', { type: 'button', class: 'btn btn-small', dataset: { breaker: name, action: 'close' }, onclick: () => command(name, true), text: 'Close' }),
              h('button', { type: 'button', class: 'btn btn-small', dataset: { breaker: name, action: 'open' }, onclick: () => command(name, false), text: 'Open' })));
          }
          return h('tr', { dataset: { breakerRow: name } }, cells);
        }));
        draw();
      }

      async function command(name, closed) {
        const label = breakerLabel(name);
        const ok = await confirmDialog(`${closed ? 'Close' : 'Open'} ${label}`,
          `${closed ? 'Close' : 'Open'} ${label} of ${status ? status.name : id}?`, { submitLabel: closed ? 'Close breaker' : 'Open breaker' });
        if (!ok) return;
        const r = await attempt(`${closed ? 'Close' : 'Open'} ${label}`, () => post(`/api/panels/${enc(id)}/breakers/${enc(name)}`, { closed }));
        if (r) { status = r; draw(); toast(`${label}: ${closed ? 'close' : 'open'} command accepted.`, 'ok'); }
      }

      async function setMode(mode) {
        const r = await attempt(`Set ${mode} mode`, () => post(`/api/panels/${enc(id)}/mode`, { mode }));
        if (r) { status = r; draw(); toast(`Panel ${id} is now in ${mode} mode.`, 'ok'); }
      }

      async function reset() {
        const name = status ? status.name : id;
        const isolated = isolatedZones(status);
        let ok;
        if (isolated.length) {
          // Reset re-energises what the sequence isolated: if the fault is still
          // there, the ELCB trips again and the whole panel goes dark.
          ok = (await formDialog(`Reset ${name}`, (form) => form.append(
            h('p', { id: `${id}-reset-zones`, text: `Reset re-energises ${isolated.join(', ')}, isolated as faulty.` }),
            h('p', { class: 'note', text: 'If the fault is not repaired, the ELCB trips again and the whole panel loses supply.' }),
            h('label', { class: 'check' }, h('input', { type: 'checkbox', name: 'repaired', id: `${id}-reset-repaired`, required: true }),
              ` The fault on ${isolated.join(', ')} is repaired`)), { submitLabel: 'Reset and re-energise', danger: true })) !== null;
        } else {
          ok = await confirmDialog(`Reset ${name}`, `Reset the fault-isolation sequence of ${name}? No zone is isolated; it clears the lockout and the last sequence's state.`, { submitLabel: 'Reset', danger: false });
        }
        if (!ok) return;
        const r = await attempt('Reset', () => post(`/api/panels/${enc(id)}/reset`));
        if (r) { status = r; draw(); toast('Reset accepted.', 'ok'); }
      }

      (async () => {
        try {
          status = await get(`/api/panels/${enc(id)}`);
        } catch (e) {
          replace(el, h('p', { class: 'error', text: `Cannot load panel ${id}: ${e.detail}` }));
          return;
        }
        if (disposed) return;
        prefix = panelPrefix(status);
        title.textContent = status.name;
        for (const k of ['Step', 'count_L_cur_c', 'count_L_cur_sv']) binder.on(`${prefix}.Seq.${k}`, drawSeq);
        const devices = await devicesUnder(prefix).catch(() => []);
        const configured = await configuredTags().catch(() => undefined);
        diagram = singleLine(binder, { prefix, title: status.name, zones: status.zones, devices, configured });
        replace(diagramBox, diagram);
        const names = ['elcb', 'mccb'].concat(Array.from({ length: status.zones }, (_, i) => `zone${i + 1}`));
        drawBreakerRows(prefix, names);
        // Only the readings this panel's analyzer has (a plant may configure a few, or none).
        const readings = ANALYZER.filter(([, tag]) => !configured || configured.has(`${prefix}.PA.${tag}`));
        replace(paBox, h('h2', { id: `pa-${id}`, text: 'Power analyzer' }),
          readings.length
            ? table(['Quantity', 'Value'], readings.map(([label, tag, units]) =>
              [label, valueEl(binder, `${prefix}.PA.${tag}`, { units })]))
            : h('p', { class: 'empty', text: 'This panel has no power analyzer readings configured.' }));
        draw();
        timer = setInterval(refresh, POLL_MS);
      })();

      // Without the live connection the sequence's status is not live either.
      const offStatus = live.onStatus((connected) => seqBox.classList.toggle('stale', !connected));
      return () => { disposed = true; clearInterval(timer); binder.dispose(); offStatus(); };
    },
  };
}
