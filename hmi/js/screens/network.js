// The switching network's single-line screen, generated from the model
// (/api/network) with an automatic layered layout: sources on the left, each
// section one column further than the nearest section feeding it. Sections
// are coloured live from their NET.Sec.<id>.State tags (docs/HMI_STYLE.md:
// energised in the voltage level's colour, dead grey, earthed hatched and
// labelled, unknown dashed with "?"), switching devices from their
// NET.Sw.<id>.Position tags, safety tags beside the device.
//
// A device is operated by select-before-operate: select (reserves it for
// this operator; others see who holds it), the preview of what it will do,
// then execute within the timeout or cancel. The result shows from the
// device's read-back.

import { get, post, del, enc } from '../api.js';
import { h, s, replace } from '../dom.js';
import { fmtTime, qualityOf, roleAtLeast } from '../format.js';
import { Binder, attempt, formDialog, toast } from '../ui.js';
import { TAG_SHORT } from '../components/singleline.js';
import { STATE_CLASSES, levelClass, levelsOf, stateClass } from '../components/netstate.js';

const COL_W = 190;
const ROW_H = 74;
const SEC_W = 120;
const SEC_H = 22;
const POLL_MS = 1000;

const KIND_WORDS = {
  circuit_breaker: 'circuit breaker', load_break_switch: 'load-break switch',
  disconnector: 'disconnector', earth_switch: 'earth switch', fuse: 'fuse',
};

/**
 * Places each section: column = hops from the nearest source section over
 * switches and transformers (sections no source reaches follow on), row =
 * order within the column, children kept near their parent. Pure: tested
 * from the browser suite through the drawn positions.
 */
export function layout(model) {
  const adj = new Map(model.sections.map((x) => [x.id, []]));
  const link = (a, b) => { if (a && b && adj.has(a) && adj.has(b)) { adj.get(a).push(b); adj.get(b).push(a); } };
  for (const w of model.switches) link(w.section, w.other_section);
  for (const t of model.transformers) link(t.section, t.other_section);
  const depth = new Map();
  const order = [];
  const queue = [];
  const visit = (id, d) => { if (!depth.has(id)) { depth.set(id, d); order.push(id); queue.push(id); } };
  for (const src of model.sources) visit(src.section, 0);
  const drain = () => {
    while (queue.length) {
      const id = queue.shift();
      for (const n of adj.get(id) || []) visit(n, depth.get(id) + 1);
    }
  };
  drain();
  // Islands no source reaches: each starts a column after the deepest.
  for (const x of model.sections) {
    if (!depth.has(x.id)) { visit(x.id, 0); drain(); }
  }
  // Rows: each column ordered by the mean row of its neighbours in the
  // column before (then after), so a feeder's sections stay side by side.
  const byCol = new Map();
  for (const id of order) {
    const d = depth.get(id);
    if (!byCol.has(d)) byCol.set(d, []);
    byCol.get(d).push(id);
  }
  const row = new Map();
  const number = (ids) => ids.forEach((id, i) => row.set(id, i));
  const colsSorted = [...byCol.keys()].sort((a, b) => a - b);
  for (const d of colsSorted) number(byCol.get(d));
  const sweep = (cols, from) => {
    for (const d of cols) {
      const ids = byCol.get(d);
      const key = new Map(ids.map((id) => {
        const ns = (adj.get(id) || []).filter((n) => depth.get(n) === d + from);
        return [id, ns.length ? ns.reduce((a, n) => a + row.get(n), 0) / ns.length : row.get(id)];
      }));
      ids.sort((a, b) => key.get(a) - key.get(b) || row.get(a) - row.get(b));
      number(ids);
    }
  };
  for (let pass = 0; pass < 2; pass++) {
    sweep(colsSorted.slice(1), -1);
    sweep(colsSorted.slice(0, -1).reverse(), 1);
  }
  sweep(colsSorted.slice(1), -1);
  const rows = new Map([...byCol].map(([d, ids]) => [d, ids.length]));
  const pos = new Map(order.map((id) => [id, { col: depth.get(id), row: row.get(id) }]));
  const cols = Math.max(1, ...[...rows.keys()].map((c) => c + 1));
  const maxRows = Math.max(1, ...rows.values());
  return { pos, cols, maxRows };
}

/**
 * Where each section's bar starts (its left end, its middle height), in
 * pixels: from the drawn screen an administrator adjusted in the screen
 * editor (`model.layout`: a line bound to a section places it), else from
 * the automatic layout. Also the drawing's size. The editor's "From
 * network" starts from the same places.
 */
export function placement(model) {
  const { pos, cols, maxRows } = layout(model);
  const auto = (id) => {
    const p = pos.get(id) || { col: 0, row: 0 };
    return { x: 50 + p.col * COL_W, y: 40 + p.row * ROW_H };
  };
  const drawn = (model.layout && model.layout.sections) || {};
  const at = new Map(model.sections.map((x) => {
    const d = drawn[x.id];
    return [x.id, d ? { x: d.x, y: d.y + Math.round(d.h / 2) } : auto(x.id)];
  }));
  let W = 80 + cols * COL_W;
  let H = 60 + maxRows * ROW_H;
  for (const p of at.values()) { W = Math.max(W, p.x + SEC_W + 60); H = Math.max(H, p.y + 50); }
  return { at, W, H, SEC_W, SEC_H };
}

export default {
  mount(el, ctx) {
    const canOperate = roleAtLeast(ctx.session.role, 'operator');
    const me = ctx.session.user;
    const binder = new Binder();
    let disposed = false;
    let timer = null;
    let model = null;
    const switchEls = new Map(); // device id -> {g, rect, stateText, tagText}
    let held = new Map(); // device id -> selection (others' and ours)

    const title = h('h1', { class: 'screen-title', text: 'Network' });
    const summary = h('p', { class: 'net-summary', id: 'net-summary' });
    const diagramBox = h('section', { class: 'card net-diagram', 'aria-label': 'Network single-line diagram' });
    const tagsBox = h('section', { class: 'card', 'aria-labelledby': 'net-tags-h' });
    const progBox = h('section', { class: 'card', 'aria-labelledby': 'net-prog-h', id: 'net-programmes' });
    el.append(title, summary, diagramBox, tagsBox, progBox);
    const canPrepare = roleAtLeast(ctx.session.role, 'supervisor');
    let openProgramme = null; // id of the programme on view
    if (!canOperate) el.insertBefore(h('p', { class: 'note', text: `View only: your role (${ctx.session.role}) may not operate the network.` }), summary);

    function draw() {
      const placed = placement(model);
      const { W, H } = placed;
      const levels = levelsOf(model);
      const svg = s('svg', { viewBox: `0 0 ${W} ${H}`, class: 'single-line net-sld', role: 'group', 'aria-label': 'Network single-line diagram' });
      // Drawn to scale and scrolled (CSSOM, which the CSP allows, not a style attribute).
      svg.style.width = `${W}px`;
      svg.style.maxWidth = 'none';
      svg.append(s('title', {}, 'Network single-line diagram'));
      const defs = s('defs', {}, s('pattern', { id: 'net-hatch', patternUnits: 'userSpaceOnUse', width: 6, height: 6, patternTransform: 'rotate(45)' },
        s('line', { x1: 0, y1: 0, x2: 0, y2: 6, class: 'net-hatch-line' })));
      svg.append(defs);
      const at = (id) => placed.at.get(id) || { x: 50, y: 40 };
      const wires = s('g', { class: 'net-wires' });
      const nodes = s('g', { class: 'net-sections' });
      const devices = s('g', { class: 'net-devices' });
      const marks = s('g', { class: 'net-marks' });
      svg.append(wires, nodes, devices, marks);
      const secParts = new Map(); // section id -> [elements coloured by its state]
      const part = (sec, elx) => { if (!secParts.has(sec)) secParts.set(sec, []); secParts.get(sec).push(elx); return elx; };
      const levelOf = (sec) => levelClass(model, levels, sec);
      // Sections: a bar each, with its customers.
      for (const x of model.sections) {
        const p = at(x.id);
        const rect = part(x.id, s('rect', { x: p.x, y: p.y - SEC_H / 2, width: SEC_W, height: SEC_H, rx: 3, class: 'net-sec' }));
        const label = s('text', { x: p.x + 6, y: p.y + 4, class: 'net-sec-label' }, x.id);
        const stateText = s('text', { x: p.x, y: p.y + SEC_H / 2 + 13, class: 'net-sec-state' }, '');
        const tip = s('title', {}, x.id);
        const g = s('g', { class: ['net-section', levelOf(x.id)], dataset: { section: x.id } }, tip, rect, label, stateText);
        if (x.customers) g.append(s('text', { x: p.x + SEC_W, y: p.y + SEC_H / 2 + 13, class: 'net-customers', 'text-anchor': 'end' }, `${x.customers} cust.`));
        nodes.append(g);
        binder.on(x.state_tag, (sample, connected) => {
          const q = qualityOf(sample, connected);
          const state = q.usable && sample ? String(sample.value) : 'UNKNOWN';
          g.classList.remove(...STATE_CLASSES);
          g.classList.add(stateClass(state));
          g.dataset.state = state;
          stateText.textContent = state === 'UNKNOWN' ? '? UNKNOWN' : state;
          tip.textContent = `${x.id}: ${state}${q.reason ? ` (${q.reason})` : ''}`;
          for (const e of secParts.get(x.id) || []) {
            e.classList.remove(...STATE_CLASSES);
            e.classList.add(stateClass(state));
          }
        });
      }
      // Sources.
      for (const src of model.sources) {
        const p = at(src.section);
        const cx = p.x - 26;
        devices.append(s('g', { class: 'net-source', dataset: { source: src.id } },
          s('title', {}, `${src.name} (${src.group})`),
          s('circle', { cx, cy: p.y, r: 11 }),
          s('text', { x: cx, y: p.y + 4, 'text-anchor': 'middle', class: 'net-source-mark' }, '~'),
          s('line', { x1: cx + 11, y1: p.y, x2: p.x, y2: p.y, class: 'net-wire' })));
      }
      // Where a device between two sections sits: just before the section
      // on the right, on its row (several feeding one section stack up and
      // down); a tie within one column is a bracket on the right. Draws the
      // wires, each coloured by the section it belongs to.
      const slots = new Map();
      const place = (secA, secB, half) => {
        const a = at(secA); const b = at(secB);
        const [l, r, ls, rs] = a.x <= b.x ? [a, b, secA, secB] : [b, a, secB, secA];
        const x1 = l.x + SEC_W;
        if (l.x === r.x) {
          const x2 = x1 + 14 + (slots.get(`tie:${ls}`) || 0) * 10;
          slots.set(`tie:${ls}`, (slots.get(`tie:${ls}`) || 0) + 1);
          const cy = (l.y + r.y) / 2;
          wires.append(part(ls, s('polyline', { points: `${x1},${l.y} ${x2},${l.y} ${x2},${cy - half}`, class: ['net-wire', levelOf(ls)] })),
            part(rs, s('polyline', { points: `${x2},${cy + half} ${x2},${r.y} ${x1},${r.y}`, class: ['net-wire', levelOf(rs)] })));
          return { cx: x2, cy, below: false, tie: true };
        }
        const j = slots.get(rs) || 0;
        slots.set(rs, j + 1);
        const cx = r.x - 24 - (half > 9 ? 4 : 0);
        const cy = r.y + (j === 0 ? 0 : (j % 2 ? 1 : -1) * Math.ceil(j / 2) * 24);
        wires.append(part(ls, s('polyline', { points: `${x1},${l.y} ${x1 + 14},${l.y} ${cx - half - 14},${cy} ${cx - half},${cy}`, class: ['net-wire', levelOf(ls)] })),
          part(rs, s('polyline', { points: `${cx + half},${cy} ${r.x - 6},${cy} ${r.x},${r.y}`, class: ['net-wire', levelOf(rs)] })));
        return { cx, cy, below: j > 0, tie: false };
      };
      // Transformers.
      for (const t of model.transformers) {
        const { cx: mx, cy: my, below } = place(t.section, t.other_section, 13);
        devices.append(s('g', { class: 'net-transformer', dataset: { transformer: t.id } }, s('title', {}, `Transformer ${t.id}`),
          s('circle', { cx: mx - 5, cy: my, r: 8 }), s('circle', { cx: mx + 5, cy: my, r: 8 }),
          s('text', { x: mx, y: below ? my + 22 : my - 12, 'text-anchor': 'middle', class: 'net-dev-label' }, t.id)));
      }
      // Switching devices: on the wire between their sections; earth
      // switches hang below their section.
      const earthCount = new Map();
      for (const w of model.switches) {
        const a = at(w.section);
        let cx; let cy; let below = false; let tie = false;
        if (w.other_section) {
          ({ cx, cy, below, tie } = place(w.section, w.other_section, 9));
        } else {
          const k = earthCount.get(w.section) || 0;
          earthCount.set(w.section, k + 1);
          cx = a.x + 14 + k * 70; cy = a.y + SEC_H / 2 + 28;
          wires.append(part(w.section, s('line', { x1: cx, y1: a.y + SEC_H / 2, x2: cx, y2: cy - 9, class: ['net-wire', levelOf(w.section)] })),
            s('line', { x1: cx - 7, y1: cy + 13, x2: cx + 7, y2: cy + 13, class: 'net-earth' }),
            s('line', { x1: cx - 4, y1: cy + 16, x2: cx + 4, y2: cy + 16, class: 'net-earth' }));
        }
        const rect = s('rect', { x: cx - 9, y: cy - 9, width: 18, height: 18, rx: 2 });
        const tip = s('title', {}, w.name);
        // The marks repeat the position and tag in the accessible name.
        const stateText = s('text', { x: cx, y: cy + 4, 'text-anchor': 'middle', class: 'net-sw-mark' }, '');
        const label = !w.other_section
          ? s('text', { x: cx + 12, y: cy + 4, class: 'net-dev-label' }, w.id)
          : tie ? s('text', { x: cx - 12, y: cy + 4, 'text-anchor': 'end', class: 'net-dev-label' }, w.id)
            : s('text', { x: cx, y: below ? cy + 22 : cy - 13, 'text-anchor': 'middle', class: 'net-dev-label' }, w.id);
        const tagText = s('text', { x: cx + 12, y: cy + 14, class: 'net-tag-mark' }, '');
        // The button holds the symbol only; its texts are drawn beside it
        // (pointer events pass through them) and said in its name.
        const g = s('g', { class: ['net-switch', `net-kind-${w.kind}`], dataset: { device: w.id }, tabindex: 0, role: 'button', 'aria-label': `${w.id}: ${w.name}, ${KIND_WORDS[w.kind] || w.kind}` },
          tip, rect);
        marks.append(s('g', { class: 'net-switch-marks', dataset: { marksOf: w.id }, 'aria-hidden': 'true' }, stateText, label, tagText));
        g.addEventListener('click', () => operate(w));
        g.addEventListener('keydown', (ev) => { if (ev.key === 'Enter' || ev.key === ' ') { ev.preventDefault(); operate(w); } });
        devices.append(g);
        const rec = { g, tip, stateText, tagText, position: 'UNKNOWN', tag: '' };
        switchEls.set(w.id, rec);
        const retitle = () => {
          const sel = held.get(w.id);
          tip.textContent = `${w.name} (${KIND_WORDS[w.kind] || w.kind}): ${rec.position}`
            + (rec.tag ? `; safety tag ${rec.tag}` : '')
            + (sel ? `; selected by ${sel.user} to ${sel.operation}` : '');
          g.setAttribute('aria-label', `${w.id}: ${tip.textContent}`);
        };
        rec.retitle = retitle;
        binder.on(`${model.prefix}.Sw.${w.id}.Position`, (sample, connected) => {
          const q = qualityOf(sample, connected);
          rec.position = q.usable && sample ? String(sample.value) : 'UNKNOWN';
          g.classList.toggle('net-closed', rec.position === 'CLOSED');
          stateText.classList.toggle('net-on-filled', rec.position === 'CLOSED');
          g.classList.toggle('net-open', rec.position === 'OPEN');
          g.classList.toggle('net-sw-unknown', rec.position !== 'CLOSED' && rec.position !== 'OPEN');
          g.dataset.position = rec.position;
          stateText.textContent = rec.position === 'CLOSED' ? 'I' : rec.position === 'OPEN' ? 'O' : '?';
          retitle();
        });
        binder.on(`${model.prefix}.Sw.${w.id}.Tag`, (sample) => {
          rec.tag = sample && typeof sample.value === 'string' ? sample.value : '';
          tagText.textContent = TAG_SHORT[rec.tag] || '';
          g.classList.toggle('net-tagged', !!rec.tag && rec.tag !== 'INFORMATION');
          g.dataset.tag = rec.tag;
          retitle();
          refreshTags();
        });
      }
      replace(diagramBox, h('div', { class: 'net-legend' },
        ...levels.map((kv, i) => h('span', { class: ['net-key', `net-lvl-${Math.min(i, 3)}`, 'net-energised'] }, h('i'), `${kv} kV energised`)),
        h('span', { class: 'net-key net-dead' }, h('i'), 'dead'),
        h('span', { class: 'net-key net-earthed' }, h('i'), 'earthed'),
        h('span', { class: 'net-key net-unknown' }, h('i'), 'unknown'),
        h('span', { class: 'net-key-text', text: 'I closed · O open · DNO/DNC safety tag' })),
      h('div', { class: 'net-scroll' }, svg));
      for (const [key, text] of [['CustomersOff', 'customers off supply'], ['CustomersUnknown', 'customers of unknown supply'], ['Loops', 'loops'], ['Parallels', 'parallels']]) {
        const v = h('strong', { id: `net-${key}` });
        summary.append(h('span', { class: 'net-total' }, v, ` ${text}`));
        binder.on(`${model.prefix}.${key}`, (sample, connected) => {
          const q = qualityOf(sample, connected);
          v.textContent = q.usable && sample ? (String(sample.value) || 'none') : '?';
        });
      }
    }

    async function pollSelections() {
      try {
        const { selections } = await get('/api/switching/selections');
        held = new Map(selections.map((x) => [x.device, x]));
        for (const [id, rec] of switchEls) {
          const sel = held.get(id);
          rec.g.classList.toggle('net-held', !!sel && sel.user !== me);
          rec.g.classList.toggle('net-mine', !!sel && sel.user === me);
          rec.g.dataset.heldBy = sel ? sel.user : '';
          rec.retitle();
        }
      } catch { /* the next poll tries again */ }
      if (!disposed) timer = setTimeout(pollSelections, POLL_MS);
    }

    let tagsPending = false;
    function refreshTags() {
      if (tagsPending) return;
      tagsPending = true;
      setTimeout(async () => {
        tagsPending = false;
        if (disposed) return;
        try {
          const { tags } = await get('/api/switching/tags');
          drawTags(tags);
        } catch (e) {
          replace(tagsBox, h('h2', { id: 'net-tags-h', text: 'Safety tags' }), h('p', { class: 'error', text: `Cannot read the safety tags: ${e.detail}` }));
        }
      }, 100);
    }

    function drawTags(tags) {
      const rows = tags.map((t) => h('tr', { dataset: { tagId: String(t.id) } },
        h('td', { text: t.device_name }), h('td', {}, h('span', { class: ['net-tag-label', `net-tag-${t.kind}`], text: t.label })),
        h('td', { text: t.reason }), h('td', { text: t.work_ref || '—' }), h('td', { text: t.placed_by }),
        h('td', { text: fmtTime(t.placed_at) }),
        h('td', {}, canOperate ? h('button', { type: 'button', class: 'btn btn-small', text: 'Remove', onclick: () => removeTag(t) }) : null)));
      replace(tagsBox, h('h2', { id: 'net-tags-h', text: 'Safety tags' }),
        tags.length ? h('table', { class: 'data net-tags' },
          h('thead', {}, h('tr', {}, ['Device', 'Tag', 'Reason', 'Work', 'Placed by', 'At', ''].map((x) => h('th', { scope: 'col', text: x })))),
          h('tbody', {}, rows)) : h('p', { class: 'hint', text: 'No safety tag stands.' }));
    }

    async function removeTag(t) {
      const form = await formDialog(`Remove ${t.label} from ${t.device_name}`, (f) => f.append(
        h('p', { text: `Placed by ${t.placed_by}: ${t.reason}` }),
        h('label', { class: 'field' }, h('span', { text: 'Reason for removal' }), h('input', { name: 'reason', required: true, maxlength: 500 }))), { submitLabel: 'Remove tag', danger: true });
      if (!form) return;
      await attempt('Removing the safety tag', () => del(`/api/switching/tags/${enc(t.id)}`, { reason: form.get('reason') }));
      refreshTags();
    }

    async function placeTag(w) {
      const form = await formDialog(`Safety tag on ${w.name}`, (f) => f.append(
        h('label', { class: 'field' }, h('span', { text: 'Kind' }), h('select', { name: 'kind' },
          h('option', { value: 'do_not_operate', text: 'Do not operate' }),
          h('option', { value: 'do_not_close', text: 'Do not close' }),
          h('option', { value: 'information', text: 'Information' }))),
        h('label', { class: 'field' }, h('span', { text: 'Reason' }), h('input', { name: 'reason', required: true, maxlength: 500 })),
        h('label', { class: 'field' }, h('span', { text: 'Work reference' }), h('input', { name: 'work_ref', maxlength: 100 }))), { submitLabel: 'Place tag' });
      if (!form) return;
      const r = await attempt('Placing the safety tag', () => post('/api/switching/tags', { device: w.id, kind: form.get('kind'), reason: form.get('reason'), work_ref: form.get('work_ref') || '' }));
      if (r) toast(`${r.label} placed on ${w.name}`, 'info');
      refreshTags();
    }

    /** The device's dialog: select-before-operate, and its safety tags. */
    async function operate(w) {
      const rec = switchEls.get(w.id);
      const op = rec.position === 'CLOSED' ? 'open' : 'close';
      const choice = await formDialog(`${w.name}`, (f) => f.append(
        h('p', { text: `${KIND_WORDS[w.kind] || w.kind}, now ${rec.position}${rec.tag ? `, safety tag ${rec.tag}` : ''}.` }),
        canOperate && w.command_tag && (!w.command_only || w.command_only === op)
          ? h('label', { class: 'field' }, h('span', { text: 'Operation' }), h('select', { name: 'op' },
            h('option', { value: op, text: op === 'open' ? 'Open' : 'Close' }),
            h('option', { value: op === 'open' ? 'close' : 'open', text: op === 'open' ? 'Close' : 'Open' })))
          : h('p', { class: 'hint', text: w.command_tag ? 'View only.' : 'No remote command: operated on site.' }),
        canOperate ? h('label', { class: 'field field-check' }, h('input', { type: 'checkbox', name: 'tag' }), h('span', { text: 'Place a safety tag instead' })) : null),
      { submitLabel: canOperate ? 'Select' : 'Close' });
      if (!choice || !canOperate) return;
      if (choice.get('tag')) { await placeTag(w); return; }
      const operation = choice.get('op');
      if (!operation) return;
      const sel = await attempt(`Selecting ${w.name}`, () => post('/api/switching/selections', { device: w.id, operation }));
      if (!sel) return;
      pollNow();
      await confirmSelection(w, sel);
      pollNow();
    }

    function pollNow() { clearTimeout(timer); if (!disposed) pollSelections(); }

    /** The preview and the countdown; execute (by `execute(sel)`, the
     * selection's own by default) or cancel. Resolves with what execute
     * answered, or undefined. */
    async function confirmSelection(w, sel, execute = (x) => post(`/api/switching/selections/${enc(x.id)}/execute`, {})) {
      const p = sel.preview;
      const list = (label, items, extra) => (items && items.length
        ? h('li', {}, `${label}: ${items.join(', ')}${extra || ''}`) : null);
      const blocked = p.interlocks.length > 0;
      // Every refusal allows an override, and this user may give it.
      const canOverride = blocked && canPrepare && p.interlocks.every((x) => x.overridable);
      const countdown = h('p', { class: 'net-countdown', id: 'net-countdown' });
      // Whole seconds left, rounded up: "0 s" only once the server's own
      // deadline has passed.
      const secondsLeft = () => Math.max(0, Math.ceil((sel.expires_at - Date.now()) / 1000));
      const show = () => {
        const left = secondsLeft();
        countdown.textContent = left > 0 ? `Execute within ${left} s, or cancel.` : 'The selection timed out: select again.';
      };
      const tick = setInterval(show, 250);
      show();
      const form = await formDialog(`${sel.operation === 'open' ? 'Open' : 'Close'} ${w.name}?`, (f) => f.append(
        h('p', { text: `Selected for you (${sel.user}); others cannot operate ${w.name} meanwhile.` }),
        h('ul', { class: 'net-preview' },
          list('Sections losing supply', p.lose_supply, ` (${p.customers_lose} customers)`),
          list('Sections gaining supply', p.gain_supply, ` (${p.customers_gain} customers)`),
          list('Newly earthed', p.newly_earthed),
          list('No longer earthed', p.no_longer_earthed),
          list('Becoming unknown', p.becomes_unknown),
          list('Sources paralleled', p.new_parallels.map((x) => x.sources.join(' + '))),
          p.loops_after !== p.loops_before ? h('li', {}, `Loops: ${p.loops_before} → ${p.loops_after}`) : null,
          !p.lose_supply.length && !p.gain_supply.length && !p.newly_earthed.length && !p.new_parallels.length
            ? h('li', {}, 'No section changes supply.') : null),
        blocked ? h('div', { class: 'net-refusals', role: 'alert' }, h('strong', { text: 'Refused:' }),
          h('ul', {}, p.interlocks.map((x) => h('li', { dataset: { rule: x.rule } }, `${x.rule}: ${x.text}${x.overridable ? ' (a supervisor may override)' : ''}`)))) : null,
        canOverride ? h('label', { class: 'field' }, h('span', { text: 'Override reason (supervisor)' }),
          h('input', { name: 'override_reason', id: 'net-override-reason', maxlength: 500 })) : null,
        countdown), { submitLabel: canOverride ? 'Override and execute' : blocked ? 'Execute (refused)' : 'Execute', danger: true });
      clearInterval(tick);
      if (!form) {
        await attempt('Cancelling the selection', () => del(`/api/switching/selections/${enc(sel.id)}`));
        return undefined;
      }
      if (secondsLeft() === 0) {
        toast(`The selection of ${w.name} timed out: nothing was sent; select again.`, 'error');
        return undefined;
      }
      const reason = canOverride ? String(form.get('override_reason') || '').trim() : '';
      if (reason) {
        const ok = await attempt(`Overriding for ${w.name}`, () => post(`/api/switching/selections/${enc(sel.id)}/override`, { reason }));
        if (!ok) return undefined;
      }
      const done = await attempt(`${sel.operation === 'open' ? 'Opening' : 'Closing'} ${w.name}`, () => execute(sel));
      if (done) toast(`${w.name}: ${sel.operation === 'open' ? 'opened' : 'closed'}, confirmed by its read-back`, 'info');
      return done;
    }


    // --- Switching programmes -------------------------------------------
    async function listProgrammes() {
      if (disposed) return;
      if (openProgramme !== null) { showProgramme(openProgramme); return; }
      let list = [];
      try {
        ({ programmes: list } = await get('/api/switching/programmes'));
      } catch (e) {
        replace(progBox, h('h2', { id: 'net-prog-h', text: 'Switching programmes' }), h('p', { class: 'error', text: `Cannot read the programmes: ${e.detail}` }));
        return;
      }
      const rows = list.map((p) => h('tr', { dataset: { programme: String(p.id) } },
        h('td', {}, h('button', { type: 'button', class: 'link-btn', text: p.name, onclick: () => showProgramme(p.id) })),
        h('td', { text: p.state }), h('td', { text: `${p.done} / ${p.steps.length}` }),
        h('td', { text: p.created_by }), h('td', { text: p.approved_by || '—' })));
      replace(progBox, h('h2', { id: 'net-prog-h', text: 'Switching programmes' }),
        canPrepare ? h('div', { class: 'btn-row' }, h('button', { type: 'button', class: 'btn', id: 'net-prog-new', text: 'New programme', onclick: newProgramme })) : null,
        list.length ? h('table', { class: 'data net-programmes' },
          h('thead', {}, h('tr', {}, ['Programme', 'State', 'Steps done', 'Prepared by', 'Approved by'].map((x) => h('th', { scope: 'col', text: x })))),
          h('tbody', {}, rows)) : h('p', { class: 'hint', text: 'No switching programme yet.' }));
    }

    /** A step's row of the builder: kind, device, operation or tag kind, text. */
    function stepRow() {
      const devices = model.switches.map((w) => h('option', { value: w.id, text: `${w.id} (${w.name})` }));
      const kind = h('select', { name: 'step-kind', 'aria-label': 'Step' },
        h('option', { value: 'operate', text: 'Operate' }), h('option', { value: 'place_tag', text: 'Place tag' }),
        h('option', { value: 'remove_tag', text: 'Remove tag' }), h('option', { value: 'manual', text: 'Manual step' }));
      const device = h('select', { name: 'step-device', 'aria-label': 'Device' }, devices);
      const operation = h('select', { name: 'step-operation', 'aria-label': 'Operation' },
        h('option', { value: 'open', text: 'open' }), h('option', { value: 'close', text: 'close' }));
      const tagKind = h('select', { name: 'step-tag-kind', 'aria-label': 'Tag kind' },
        h('option', { value: 'do_not_operate', text: 'Do not operate' }), h('option', { value: 'do_not_close', text: 'Do not close' }),
        h('option', { value: 'information', text: 'Information' }));
      const text = h('input', { name: 'step-text', 'aria-label': 'Reason or instruction', placeholder: 'reason / instruction', maxlength: 500 });
      const remove = h('button', { type: 'button', class: 'btn btn-small', text: '✕', 'aria-label': 'Remove this step' });
      const row = h('li', { class: 'net-step-row' }, kind, device, operation, tagKind, text, remove);
      const sync = () => {
        const k = kind.value;
        device.hidden = k === 'manual';
        operation.hidden = k !== 'operate';
        tagKind.hidden = !(k === 'place_tag' || k === 'remove_tag');
        text.hidden = !(k === 'place_tag' || k === 'manual');
      };
      kind.addEventListener('change', sync);
      remove.addEventListener('click', () => row.remove());
      sync();
      row.step = () => {
        switch (kind.value) {
          case 'operate': return { kind: 'operate', device: device.value, operation: operation.value };
          case 'place_tag': return { kind: 'place_tag', device: device.value, tag_kind: tagKind.value, reason: text.value, work_ref: '' };
          case 'remove_tag': return { kind: 'remove_tag', device: device.value, tag_kind: tagKind.value };
          default: return { kind: 'manual', text: text.value };
        }
      };
      return row;
    }

    async function newProgramme() {
      const list = h('ol', { class: 'net-step-list', id: 'net-step-list' }, stepRow());
      const form = await formDialog('New switching programme', (f) => f.append(
        h('label', { class: 'field' }, h('span', { text: 'Name' }), h('input', { name: 'name', required: true, maxlength: 200 })),
        list,
        h('button', { type: 'button', class: 'btn btn-small', id: 'net-step-add', text: 'Add step', onclick: () => list.append(stepRow()) })), { submitLabel: 'Prepare' });
      if (!form) return;
      const steps = [...list.children].map((row) => row.step());
      const p = await attempt('Preparing the programme', () => post('/api/switching/programmes', { name: form.get('name'), steps }));
      if (p) showProgramme(p.id);
    }

    async function showProgramme(id) {
      openProgramme = id;
      let p;
      try {
        p = await get(`/api/switching/programmes/${enc(id)}`);
      } catch (e) {
        openProgramme = null;
        toast(`Programme ${id}: ${e.detail}`, 'error');
        listProgrammes();
        return;
      }
      if (disposed) return;
      const back = h('button', { type: 'button', class: 'btn btn-small', text: 'All programmes', onclick: () => { openProgramme = null; listProgrammes(); } });
      const blocked = p.steps.some((st) => st.check && st.check.refusals.length);
      const act = (label, idAttr, f, danger = false) => h('button', { type: 'button', class: ['btn', danger ? 'btn-danger' : null], id: idAttr, text: label, onclick: f });
      const buttons = [];
      const live = ['approved', 'running'].includes(p.state);
      if (p.state === 'draft' && canPrepare) buttons.push(act('Approve', 'net-prog-approve', () => progAction(p, 'approve')));
      if (live && canOperate && p.done < p.steps.length) buttons.push(act(`Do step ${p.done + 1}`, 'net-prog-step', () => doStep(p)));
      if (live && canOperate) buttons.push(act('Pause', 'net-prog-pause', () => progState(p, 'pause')));
      if (p.state === 'paused' && canOperate) buttons.push(act('Resume', 'net-prog-resume', () => progState(p, 'resume')));
      if (['draft', 'approved', 'running', 'paused'].includes(p.state) && canOperate && (p.state !== 'draft' || canPrepare)) buttons.push(act('Abandon', 'net-prog-abandon', () => progState(p, 'abandon'), true));
      const stepEl = (st) => {
        const c = st.check;
        const bits = [];
        if (c) {
          if (c.lose_supply.length) bits.push(`${c.lose_supply.join(', ')} lose supply (${c.customers_lose} customers)`);
          if (c.gain_supply.length) bits.push(`${c.gain_supply.join(', ')} gain supply (${c.customers_gain} customers)`);
          if (c.newly_earthed.length) bits.push(`${c.newly_earthed.join(', ')} earthed`);
          if (c.no_longer_earthed.length) bits.push(`${c.no_longer_earthed.join(', ')} no longer earthed`);
          bits.push(...c.notes);
        }
        return h('li', { class: ['net-step', st.done ? 'net-step-done' : null, st.n === p.done + 1 ? 'net-step-next' : null], dataset: { step: String(st.n) } },
          h('span', { class: 'net-step-text', text: `${st.done ? '✓ ' : ''}${st.text}` }),
          bits.length ? h('span', { class: 'net-step-effect', text: ` — ${bits.join('; ')}` }) : null,
          c && c.refusals.length ? h('div', { class: 'net-refusals', role: 'alert' },
            h('ul', {}, c.refusals.map((x) => h('li', { dataset: { rule: x.rule } }, `${x.rule}: ${x.text}`)))) : null);
      };
      replace(progBox, h('h2', { id: 'net-prog-h', text: `Programme ${p.id}: ${p.name}` }),
        h('p', { class: 'net-prog-state', id: 'net-prog-state', dataset: { state: p.state } },
          `${p.state.toUpperCase()} · ${p.done} of ${p.steps.length} steps done · prepared by ${p.created_by}`
          + (p.approved_by ? ` · approved by ${p.approved_by}` : '') + (p.note ? ` · ${p.note}` : '')),
        blocked && p.state === 'draft' ? h('p', { class: 'hint', text: 'Approval waits until no step is refused on the network as it is.' }) : null,
        h('ol', { class: 'net-steps' }, p.steps.map(stepEl)),
        h('div', { class: 'btn-row' }, back, ...buttons));
    }

    async function progAction(p, action) {
      await attempt(`Programme ${p.id}`, () => post(`/api/switching/programmes/${enc(p.id)}/${action}`, {}));
      showProgramme(p.id);
    }

    async function progState(p, action) {
      let reason = '';
      if (action === 'abandon') {
        const form = await formDialog(`Abandon programme ${p.id}`, (f) => f.append(
          h('label', { class: 'field' }, h('span', { text: 'Reason' }), h('input', { name: 'reason', required: true, maxlength: 500 }))), { submitLabel: 'Abandon', danger: true });
        if (!form) return;
        reason = form.get('reason');
      }
      await attempt(`Programme ${p.id}`, () => post(`/api/switching/programmes/${enc(p.id)}/state`, { action, reason }));
      showProgramme(p.id);
    }

    /** The next step: an operate step through select-before-operate, the others confirmed. */
    async function doStep(p) {
      const st = p.steps[p.done];
      const stepUrl = `/api/switching/programmes/${enc(p.id)}/step`;
      const w = st.step.device ? model.switches.find((x) => x.id === st.step.device) : null;
      if (st.step.kind === 'operate' && w && w.command_tag) {
        const sel = await attempt(`Selecting ${w.name}`, () => post('/api/switching/selections', { device: w.id, operation: st.step.operation }));
        if (!sel) return;
        pollNow();
        await confirmSelection(w, sel, (x) => post(stepUrl, { selection: x.id, version: p.version }));
        pollNow();
      } else {
        const ok = await formDialog(`Step ${st.n}`, (f) => f.append(h('p', { text: st.text }),
          st.step.kind === 'operate' ? h('p', { class: 'hint', text: 'Operated on site: confirm once its status reads the new position.' }) : null),
        { submitLabel: st.step.kind === 'manual' ? 'Confirm done' : 'Do it', danger: false });
        if (!ok) return;
        await attempt(`Step ${st.n}`, () => post(stepUrl, { version: p.version }));
      }
      showProgramme(p.id);
    }

    (async () => {
      try {
        model = await get('/api/network');
      } catch (e) {
        replace(diagramBox, h('p', { class: 'error', text: `Cannot read the network: ${e.detail}` }));
        return;
      }
      if (disposed) return;
      draw();
      refreshTags();
      pollSelections();
      listProgrammes();
    })();

    return () => {
      disposed = true;
      clearTimeout(timer);
      binder.dispose();
    };
  },
};
