// Single-line diagram of one substation panel, drawn in SVG and kept live:
// supply, ELCB, MCCB, busbar, zone breakers and zone loads, with the power
// analyzer and the communication status of each I/O module. Colours follow
// docs/HMI_STYLE.md: breakers are grey, filled when closed and hollow when
// open (a deliberate open is not red), red only when TRIPPED, and ALWAYS
// labelled CLOSED / OPEN / TRIPPED, so colour is never the only signal.
// Unknown quality shows "?".

import { s } from '../dom.js';
import { decimalsOf, fmtNumber, qualityOf } from '../format.js';
import { live } from '../live.js';

const MIN_W = 640;
const H = 400;
/** Room per zone, so labels stay legible from 1 to 32 zones (wide panels scroll). */
const ZONE_W = 100;
/** A safety tag's short mark beside its device (as on the network screen). */
export const TAG_SHORT = { 'DO NOT OPERATE': 'DNO', 'DO NOT CLOSE': 'DNC', INFORMATION: 'i' };

/** Breaker state from its feedback and (if any) its command tag. */
export function breakerState(closed, cmd, connected, isElcb = false) {
  const q = qualityOf(closed, connected);
  if (!q.usable || typeof closed.value !== 'boolean') return { label: 'UNKNOWN', cls: 'bk-unknown', reason: q.reason || 'no value' };
  if (closed.value) return { label: 'CLOSED', cls: 'bk-closed', reason: '' };
  // Open while commanded closed means the protection opened it.
  const cmdClosed = cmd && qualityOf(cmd, connected).usable && cmd.value === true;
  if (isElcb || cmdClosed) return { label: 'TRIPPED', cls: 'bk-tripped', reason: '' };
  return { label: 'OPEN', cls: 'bk-open', reason: '' };
}

/**
 * Builds the diagram of the panel whose tags start with `prefix`; `binder`
 * keeps it live. `devices` are the I/O modules and analyzer shown with their
 * communication status. `onBreaker(name)` (optional) makes breakers clickable.
 * `configured` (a set of tag names) leaves out the signals a plant does not
 * have: a zone load without an Energised tag shows no state, a panel without
 * a door contact no door, an analyzer only its configured readings.
 */
export function singleLine(binder, { prefix, title, zones = 4, devices = [], onBreaker, configured }) {
  const has = (tag) => !configured || configured.has(tag);
  const W = Math.max(MIN_W, 90 + zones * ZONE_W);
  const svg = s('svg', { viewBox: `0 0 ${W} ${H}`, class: 'single-line', role: 'img', 'aria-label': `Single-line diagram of ${title}`, dataset: { zones: String(zones) } });
  // Wider than the standard panel: fit the card down to 80 % of the text
  // size (7 or 8 zones fit a 1366-px screen, no label cut at the card's
  // edge), and scroll beyond that (a 32-zone panel).
  if (W > MIN_W) { svg.classList.add('single-line-wide'); svg.style.width = `max(100%, ${Math.round(W * 0.8)}px)`; svg.style.maxWidth = 'none'; }
  svg.append(s('title', {}, `Single-line diagram of ${title}`));
  // What the panel's sequence says (set through box.panelStatus): faulty
  // zones it isolated, and manual mode (automatic isolation off).
  const marks = { faulty: new Set(), manual: false, safety: {} };
  const redraws = [];
  const manualText = s('text', { x: 12, y: 76, class: 'sl-manual', visibility: 'hidden' });
  replaceText(manualText, [['MANUAL ', 0], ['automatic ', 15], ['isolation off', 14]], 12);
  svg.append(manualText);
  const cx = 130;
  // Supply.
  svg.append(
    s('circle', { cx, cy: 28, r: 14, class: 'sl-source' }),
    s('text', { x: cx + 22, y: 32, class: 'sl-label' }, 'Supply 400 V'),
    s('line', { x1: cx, y1: 42, x2: cx, y2: 62, class: 'sl-wire' }));

  const breaker = (x, y, name, label, closedTag, cmdTag, isElcb) => {
    const g = s('g', { class: 'sl-breaker', dataset: { breaker: name } });
    const rect = s('rect', { x: x - 13, y: y - 13, width: 26, height: 26, rx: 3 });
    const stateText = s('text', { x: x + 20, y: y + 15, class: 'sl-state' }, '');
    // A safety tag on the breaker (the network's): DNO / DNC below it, left of the wire, as on the network screen.
    const tagText = s('text', { x: x - 6, y: y + 32, class: 'net-tag-mark sl-end' }, '');
    const tip = s('title', {}, '');
    g.append(tip, rect, s('text', { x: x + 20, y: y - 1, class: 'sl-label' }, label), stateText, tagText);
    if (onBreaker) {
      g.setAttribute('tabindex', '0');
      g.setAttribute('role', 'button');
      g.classList.add('sl-clickable');
      g.addEventListener('click', () => onBreaker(name));
      g.addEventListener('keydown', (e) => { if (e.key === 'Enter' || e.key === ' ') { e.preventDefault(); onBreaker(name); } });
    }
    const draw = (_x, connected) => {
      const st = breakerState(binder.sample(closedTag), cmdTag ? binder.sample(cmdTag) : null, connected, isElcb);
      const safety = marks.safety[name];
      const tagged = safety && safety.kind !== 'information';
      g.setAttribute('class', `sl-breaker ${st.cls}${onBreaker ? ' sl-clickable' : ''}${tagged ? ' sl-tagged' : ''}`);
      g.dataset.tag = safety ? safety.label : '';
      tagText.textContent = safety ? (TAG_SHORT[safety.label] || '') : '';
      stateText.textContent = st.label === 'UNKNOWN' ? '? UNKNOWN' : st.label;
      tip.textContent = `${label}: ${st.label}${st.reason ? ` (${st.reason})` : ''}${safety ? `; ${(safety.tags || []).join('; ')}` : ''}`;
      g.setAttribute('aria-label', tip.textContent);
    };
    binder.on(closedTag, draw);
    if (cmdTag) binder.on(cmdTag, draw);
    redraws.push(() => draw(null, live.connected));
    return g;
  };

  svg.append(breaker(cx, 75, 'elcb', 'ELCB', `${prefix}.ELCB.Closed`, null, true));
  svg.append(s('line', { x1: cx, y1: 88, x2: cx, y2: 122, class: 'sl-wire' }));
  svg.append(breaker(cx, 135, 'mccb', 'MCCB', `${prefix}.MCCB.Closed`, `${prefix}.MCCB.Cmd`, false));
  svg.append(s('line', { x1: cx, y1: 148, x2: cx, y2: 180, class: 'sl-wire' }));

  // Busbar and zones.
  const left = 50;
  const right = W - 40;
  // The last zone's state is written right of its breaker: leave room for
  // the widest, "? UNKNOWN" (a lost module), inside the card.
  const step = (right - 20 - left) / zones;
  svg.append(s('line', { x1: left, y1: 180, x2: right, y2: 180, class: 'sl-bus' }),
    s('text', { x: right - 4, y: 172, class: 'sl-label sl-end' }, 'Busbar'));
  for (let z = 1; z <= zones; z++) {
    const x = left + step * (z - 0.5);
    svg.append(
      s('line', { x1: x, y1: 180, x2: x, y2: 212, class: 'sl-wire' }),
      breaker(x, 225, `zone${z}`, `Zone ${z}`, `${prefix}.Zone${z}.Closed`, `${prefix}.Zone${z}.Cmd`, false),
      s('line', { x1: x, y1: 238, x2: x, y2: 268, class: 'sl-wire' }));
    // The zone's load, filled grey when energised.
    const load = s('g', { class: 'sl-load', dataset: { zone: String(z) } });
    const tri = s('path', { d: `M ${x - 12} 270 L ${x + 12} 270 L ${x} 290 Z` });
    const txt = s('text', { x, y: 308, class: 'sl-state sl-middle' }, '');
    const tip = s('title', {}, '');
    load.append(tip, tri, txt);
    const energisedTag = `${prefix}.Zone${z}.Energised`;
    const measured = has(energisedTag);
    const drawLoad = (smp, connected) => {
      const q = qualityOf(smp, connected);
      const on = q.usable && smp.value === true;
      if (marks.faulty.has(z)) {
        // Isolated by the sequence as faulty: say so, on two lines to stay legible.
        load.setAttribute('class', 'sl-load io-faulty');
        replaceText(txt, [['FAULTY – ', 0], ['ISOLATED', 13]], x);
        tip.textContent = `Zone ${z}: found faulty and isolated by the sequence; repair it before Reset`;
        return;
      }
      if (!measured) {
        // No voltage signal on this zone's load: the breaker above says all there is.
        load.setAttribute('class', 'sl-load io-unmeasured');
        txt.textContent = '';
        tip.textContent = `Zone ${z} load (no voltage signal configured)`;
        return;
      }
      // Energised and dead are normal states (grey, filled or hollow): a zone opened on purpose is not an alarm.
      load.setAttribute('class', `sl-load ${!q.usable ? 'io-unknown' : on ? 'io-true io-energised' : 'io-dead'}`);
      txt.textContent = !q.usable ? '? UNKNOWN' : on ? 'ENERGISED' : 'DEAD';
      tip.textContent = `Zone ${z} load: ${txt.textContent}${q.reason ? ` (${q.reason})` : ''}`;
    };
    if (measured) binder.on(energisedTag, drawLoad);
    else drawLoad(null, true);
    redraws.push(() => drawLoad(binder.sample(energisedTag), live.connected));
    svg.append(load);
  }

  // Power analyzer readings beside the incomer.
  const pa = s('g', { class: 'sl-pa' });
  pa.append(s('rect', { x: 260, y: 20, width: 210, height: 140, rx: 4, class: 'sl-box' }),
    s('text', { x: 270, y: 38, class: 'sl-label sl-bold' }, 'Power analyzer'));
  // Voltages in the first column, currents in the second, power below; a
  // reading the plant does not configure leaves its place empty.
  const rows = [['V L1', 'V_L1', 'V', 0, 0], ['V L2', 'V_L2', 'V', 0, 1], ['V L3', 'V_L3', 'V', 0, 2],
    ['I L1', 'I_L1', 'A', 1, 0], ['I L2', 'I_L2', 'A', 1, 1], ['I L3', 'I_L3', 'A', 1, 2], ['P', 'P_kW', 'kW', 0, 3]]
    .filter(([, tag]) => has(`${prefix}.PA.${tag}`));
  rows.forEach(([label, tag, units, col, row]) => {
    const x = 270 + col * 105;
    const y = 60 + row * 22;
    const t = s('text', { x, y, class: 'sl-value' }, '');
    const tip = s('title', {}, '');
    t.append(tip);
    const name = `${prefix}.PA.${tag}`;
    binder.on(name, (smp, connected) => {
      const q = qualityOf(smp, connected);
      t.setAttribute('class', `sl-value ${q.cls}`);
      t.firstChild && t.firstChild.nodeType === 3 && t.firstChild.remove();
      const text = q.usable && typeof smp.value === 'number' ? `${label} ${fmtNumber(smp.value, decimalsOf(name))} ${units}` : `${label} ?`;
      t.insertBefore(document.createTextNode(text), tip);
      tip.textContent = q.reason || `${label} ${text}`;
    });
    pa.append(t);
  });
  if (rows.length) svg.append(pa);

  // Door and communication status of each module.
  const status = s('g', { class: 'sl-status' });
  // An open door is abnormal (amber); a lost module is an alarm (red).
  const items = [{ label: 'Door', tag: `${prefix}.Door.Open`, text: (v) => (v ? 'OPEN' : 'CLOSED'), good: (v) => !v, notGood: 'io-abnormal' }]
    .filter((it) => has(it.tag))
    .concat(devices.map((d) => ({ label: d.replace(`${prefix}.`, ''), tag: `${d}.Comm.Connected`, text: (v) => (v ? 'COMM OK' : 'COMM LOST'), good: (v) => !!v, notGood: 'io-false' })));
  items.forEach((it, i) => {
    const x = 20 + i * 122;
    const g = s('g', { class: 'sl-io' });
    const lamp = s('circle', { cx: x + 8, cy: 352, r: 7 });
    const t = s('text', { x: x + 20, y: 348, class: 'sl-label' }, it.label);
    const st = s('text', { x: x + 20, y: 366, class: 'sl-state' }, '');
    const tip = s('title', {}, '');
    g.append(tip, lamp, t, st);
    binder.on(it.tag, (smp, connected) => {
      const q = qualityOf(smp, connected);
      const ok = q.usable && it.good(smp.value);
      g.setAttribute('class', `sl-io ${!q.usable ? 'io-unknown' : ok ? 'io-true' : it.notGood}`);
      st.textContent = q.usable ? it.text(smp.value) : '? UNKNOWN';
      tip.textContent = `${it.label}: ${st.textContent}${q.reason ? ` (${q.reason})` : ''}`;
    });
    status.append(g);
  });
  svg.append(s('line', { x1: 10, y1: 330, x2: W - 10, y2: 330, class: 'sl-sep' }), status);
  // A wide panel scrolls sideways inside its card instead of shrinking its text.
  const box = document.createElement('div');
  box.className = 'sl-scroll';
  // A region that may scroll is reachable from the keyboard.
  box.tabIndex = 0;
  box.setAttribute('role', 'group');
  box.setAttribute('aria-label', `${title}: diagram`);
  box.append(svg);
  /**
   * Marks the faulty zones the sequence isolated, manual mode, and the safety
   * tags on the breakers (with a switching network), from the panel's status.
   */
  box.panelStatus = (status) => {
    if (!status) return;
    const faulty = new Set((status.faulty_zones || []).map(Number));
    const manual = status.mode === 'manual';
    const safety = status.safety_tags || {};
    const changed = manual !== marks.manual || faulty.size !== marks.faulty.size || [...faulty].some((z) => !marks.faulty.has(z))
      || JSON.stringify(safety) !== JSON.stringify(marks.safety);
    if (!changed) return;
    marks.faulty = faulty;
    marks.manual = manual;
    marks.safety = safety;
    manualText.setAttribute('visibility', manual ? 'visible' : 'hidden');
    svg.classList.toggle('sl-is-manual', manual);
    for (const f of redraws) f();
  };
  return box;
}

/** Sets an SVG text to lines of [text, dy] tspans (textContent stays the words joined). */
function replaceText(el, lines, x) {
  el.replaceChildren(...lines.map(([t, dy]) => s('tspan', { x, dy: dy || 0 }, t)));
}
