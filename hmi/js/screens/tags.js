// Tag browser: the tag tree (dot-separated names, loaded a level at a time),
// a search box, a virtualised list of the matching tags (filtered and paged
// on the server, so 100,000 tags stay light), and the selected tag's
// details: value with units, quality with its reason, timestamp, and where it
// comes from (device, table, address, data type, word order). Writable tags
// have a confirmed write that shows the device's read-back.

import { get, post, qs, enc } from '../api.js';
import { h, replace, field, select } from '../dom.js';
import { fmtStated, fmtTime, fmtValue, noteTags, qualityOf, roleAtLeast, showSample, stateWord } from '../format.js';
import { live } from '../live.js';
import { Binder, attempt, formDialog, confirmDialog, toast } from '../ui.js';

const ROW_H = 30;

/** The device protocol as an engineer names it. */
function protocolName(p) {
  return { tcp: 'Modbus TCP', rtu: 'Modbus RTU', iec104: 'IEC 60870-5-104', dnp3: 'DNP3' }[p] || p;
}
const PAGE = 200;

/** A tag with `states` shows its values in those words (OPEN, CLOSED), not TRUE/FALSE. */
function wordsOf(t) {
  return t.states ? (v) => fmtStated(t.states, v, t.decimals ?? undefined) : undefined;
}

/** A value the operator typed: in the tag's words where it has them, else as typed (not rounded to its decimals). */
function typedText(tag, v) {
  return stateWord(tag.states, v) ?? (typeof v === 'number' ? String(v) : fmtValue(v));
}

/** A tag's engineering limits in the server's words ("0 to 100", "at least 0"), or ''. */
export function limitsText(limits) {
  if (!limits) return '';
  const has = (v) => v !== null && v !== undefined;
  if (has(limits.min) && has(limits.max)) return `${limits.min} to ${limits.max}`;
  if (has(limits.min)) return `at least ${limits.min}`;
  if (has(limits.max)) return `at most ${limits.max}`;
  return '';
}

/** Why `typed` may not be written to `tag`, as the server says it, or ''. */
export function outsideLimits(tag, typed) {
  const range = limitsText(tag.limits);
  const text = String(typed).trim();
  if (!range || text === '') return '';
  const v = Number(text);
  const { min, max } = tag.limits;
  const inside = Number.isFinite(v) && (min === null || min === undefined || v >= min) && (max === null || max === undefined || v <= max);
  return inside ? '' : `${text} is outside the engineering limits of '${tag.name}' (${range}); nothing was written`;
}

/** The write dialog of a tag; resolves with the typed value or undefined. */
export async function askValue(tag, current) {
  const input = tag.kind === 'bool'
    ? select({ name: 'value', id: 'write-value' }, [['true', `${fmtStated(tag.states, true)} (1)`], ['false', `${fmtStated(tag.states, false)} (0)`]], current === true ? 'true' : 'false')
    : h('input', {
      name: 'value', id: 'write-value', required: true,
      // An integer is typed as digits: a number input rounds beyond 2^53.
      type: tag.kind === 'float' ? 'number' : 'text',
      step: tag.kind === 'float' ? 'any' : undefined,
      inputmode: tag.kind === 'int' ? 'numeric' : undefined,
      pattern: tag.kind === 'int' ? '[-+]?[0-9]+' : undefined,
      value: current === undefined || current === null ? '' : String(current),
    });
  // The engineering limits before the operator types, and a value outside
  // them refused here in the server's words (it would refuse it too).
  const range = limitsText(tag.limits);
  if (range && tag.kind !== 'bool') {
    if (tag.limits.min !== null && tag.limits.min !== undefined) input.min = String(tag.limits.min);
    if (tag.limits.max !== null && tag.limits.max !== undefined) input.max = String(tag.limits.max);
    input.addEventListener('input', () => input.setCustomValidity(outsideLimits(tag, input.value) || ''));
  }
  const data = await formDialog(`Write ${tag.name}`, (f) => f.append(
    h('p', { class: 'hint', text: tag.description || '' }),
    range ? h('p', { class: 'hint', id: 'write-limits', text: `Engineering limits: ${range}${tag.units ? ` ${tag.units}` : ''}` }) : '',
    field(`New value${tag.units ? ` (${tag.units})` : ''}`, input)), { submitLabel: 'Next' });
  if (!data) return undefined;
  const raw = data.get('value');
  if (tag.kind === 'bool') return raw === 'true';
  // An integer beyond 2^53 goes as its digits, which the server takes exactly.
  if (tag.kind === 'int') {
    const t = String(raw).trim();
    const n = Number.parseInt(t, 10);
    return /^[-+]?\d+$/.test(t) && !Number.isSafeInteger(n) ? t : n;
  }
  if (tag.kind === 'float') return Number(raw);
  return String(raw);
}

/**
 * Writes `value` to `tag` after the operator confirms; shows the value the
 * device read back, or why it failed, in words. Resolves with the tag view.
 */
export async function confirmedWrite(tag, value) {
  const ok = await confirmDialog(`Write ${tag.name}`,
    `Write ${typedText(tag, value)}${tag.units ? ` ${tag.units}` : ''} to ${tag.name}? The device is commanded at once.`,
    { submitLabel: 'Write', danger: true });
  if (!ok) return undefined;
  const r = await attempt(`Write ${tag.name}`, () => post(`/api/tags/${enc(tag.name)}/write`, { value }));
  if (r) toast(`${tag.name}: the device confirmed ${fmtStated(tag.states, r.value, tag.decimals ?? undefined)}${r.units ? ` ${r.units}` : ''}.`, 'ok');
  return r;
}

export default {
  mount(el, ctx) {
    const role = ctx.session.role;
    const binder = new Binder();
    let disposed = false;
    let filter = { prefix: '', search: '' };
    let total = 0;
    let pages = new Map(); // page index -> tags (or a promise)
    let generation = 0;
    let selected = null;
    let detailBinder = null;

    const search = h('input', { type: 'search', id: 'tag-search', placeholder: 'Search names and descriptions', 'aria-label': 'Search tags', size: 28 });
    const where = h('p', { class: 'hint', id: 'tag-where', role: 'status' });
    const tree = h('ul', { class: 'tag-tree', id: 'tag-tree', role: 'tree', 'aria-label': 'Tag tree' });
    const spacer = h('div', { class: 'vlist-spacer' });
    const rows = h('div', { class: 'vlist-rows' });
    const list = h('div', { class: 'vlist', id: 'tag-list', role: 'listbox', 'aria-label': 'Tags', tabindex: '0' }, spacer, rows);
    const detail = h('section', { class: 'card tag-detail', id: 'tag-detail', 'aria-label': 'Selected tag' },
      h('p', { class: 'empty', text: 'Select a tag to see its details.' }));
    el.append(h('h1', { class: 'screen-title', text: 'Tags' }),
      h('div', { class: 'tags-layout' },
        h('section', { class: 'card tags-tree-card', 'aria-label': 'Tree' },
          h('button', { type: 'button', class: 'btn btn-small', id: 'tag-tree-all', text: 'All tags', onclick: () => setFilter({ prefix: '' }) }),
          tree),
        h('section', { class: 'card tags-list-card', 'aria-label': 'Tags' },
          h('div', { class: 'filters' }, field('Search', search)), where, list),
        detail));

    // --- tree -------------------------------------------------------------
    async function loadChildren(prefix, ul) {
      try {
        const r = await get(`/api/tags/tree${qs({ prefix })}`);
        replace(ul, r.children.map((c) => {
          const sub = h('ul', { role: 'group', hidden: true });
          const toggle = h('button', {
            type: 'button', class: 'tree-toggle', 'aria-label': `Expand ${c.name}`, 'aria-expanded': 'false',
            text: c.has_children ? '▸' : '·', disabled: !c.has_children,
          });
          toggle.addEventListener('click', async () => {
            const open = sub.hidden;
            sub.hidden = !open;
            toggle.textContent = open ? '▾' : '▸';
            toggle.setAttribute('aria-expanded', String(open));
            if (open && !sub.childElementCount) await loadChildren(`${c.name}.`, sub);
          });
          const label = h('button', {
            type: 'button', class: 'tree-label', dataset: { node: c.name }, title: `${c.count} tags`,
            text: `${c.label} (${c.count})`,
          });
          label.addEventListener('click', () => {
            if (c.is_tag && !c.has_children) setFilter({ prefix: c.name }, c.name);
            else setFilter({ prefix: `${c.name}.` });
          });
          return h('li', { role: 'treeitem' }, toggle, label, sub);
        }));
      } catch (e) {
        replace(ul, h('li', { class: 'error', text: `Cannot load the tree: ${e.detail}` }));
      }
    }

    // --- list (virtualised, pages from the server) ------------------------
    function setFilter(f, select) {
      filter = { ...filter, ...f };
      generation += 1;
      pages = new Map();
      total = 0;
      list.scrollTop = 0;
      fetchPage(0).then(() => {
        if (select) { const t = find(select); if (t) choose(t); }
      });
    }

    function find(name) {
      for (const p of pages.values()) {
        if (Array.isArray(p)) { const t = p.find((x) => x.name === name); if (t) return t; }
      }
      return null;
    }

    async function fetchPage(i) {
      if (pages.has(i)) return pages.get(i);
      const gen = generation;
      const promise = get(`/api/tags${qs({ prefix: filter.prefix, search: filter.search, offset: i * PAGE, limit: PAGE })}`)
        .then((r) => {
          if (gen !== generation || disposed) return null;
          pages.set(i, noteTags(r.tags));
          total = r.total;
          where.textContent = `${total} tag${total === 1 ? '' : 's'}${filter.prefix ? ` under ${filter.prefix}` : ''}${filter.search ? ` matching "${filter.search}"` : ''}`;
          render();
          return r.tags;
        })
        .catch((e) => {
          pages.delete(i);
          where.textContent = `Cannot list tags: ${e.detail}`;
          return null;
        });
      pages.set(i, promise);
      return promise;
    }

    let watched = { tags: [] };
    let offWatch = live.want(watched);
    function render() {
      spacer.style.height = `${total * ROW_H}px`;
      const first = Math.max(0, Math.floor(list.scrollTop / ROW_H) - 5);
      const last = Math.min(total, first + Math.ceil((list.clientHeight || 500) / ROW_H) + 10);
      const shown = [];
      for (let i = first; i < last; i++) {
        const page = pages.get(Math.floor(i / PAGE));
        if (!Array.isArray(page)) { fetchPage(Math.floor(i / PAGE)); continue; }
        const t = page[i % PAGE];
        if (t) shown.push([i, t]);
      }
      replace(rows, shown.map(([i, t]) => {
        const value = h('span', { class: 'value' });
        const s = live.get(t.name) || t;
        showSample(value, s, { units: t.units, kind: t.kind, tag: t.name, live: live.connected, format: wordsOf(t) });
        const row = h('div', {
          class: ['vlist-row', selected === t.name && 'selected'], role: 'option', 'aria-selected': String(selected === t.name),
          dataset: { tag: t.name }, tabindex: '-1',
        }, h('span', { class: 'tag-name', title: t.description, text: t.name }), value);
        row.style.top = `${i * ROW_H}px`;
        row.addEventListener('click', () => choose(t));
        return row;
      }));
      // Live values for exactly the rows on view.
      const names = shown.map(([, t]) => t.name);
      if (names.join() !== watched.tags.join()) {
        offWatch();
        watched = { tags: names };
        offWatch = live.want(watched);
      }
    }
    list.addEventListener('scroll', () => requestAnimationFrame(render));
    const offTags = live.onTags(() => render());

    let searchTimer = null;
    search.addEventListener('input', () => {
      clearTimeout(searchTimer);
      searchTimer = setTimeout(() => setFilter({ search: search.value.trim() }), 200);
    });

    // --- detail -------------------------------------------------------------
    function choose(t) {
      selected = t.name;
      render();
      if (detailBinder) detailBinder.dispose();
      detailBinder = new Binder();
      const value = h('span', { class: 'value', id: 'tag-value' });
      const quality = h('dd', { id: 'tag-quality' });
      const stamp = h('dd', { id: 'tag-timestamp' });
      detailBinder.on(t.name, (smp, connected) => {
        showSample(value, smp, { units: t.units, kind: t.kind, tag: t.name, live: connected, format: wordsOf(t) });
        const q = qualityOf(smp, connected);
        quality.textContent = q.cls === 'q-good' ? 'Good' : `${q.cls === 'q-uncertain' ? 'Uncertain' : 'Bad'}: ${q.reason}`;
        quality.className = q.cls === 'q-good' ? '' : q.cls === 'q-uncertain' ? 'badge badge-warn' : 'badge badge-bad';
        stamp.textContent = smp ? fmtTime(smp.timestamp, true) : '—';
      });
      const src = t.source;
      const may = t.writable && t.write_role && roleAtLeast(role, t.write_role);
      const writeBtn = may ? h('button', { type: 'button', class: 'btn btn-primary', id: 'tag-write', text: 'Write…' }) : null;
      if (writeBtn) {
        writeBtn.addEventListener('click', async () => {
          const cur = live.get(t.name);
          const v = await askValue(t, cur ? cur.value : undefined);
          if (v === undefined || (typeof v === 'number' && !Number.isFinite(v))) return;
          const r = await confirmedWrite(t, v);
          if (r) readback.textContent = `Confirmed by the device: ${fmtStated(t.states, r.value, t.decimals ?? undefined)}${t.units ? ` ${t.units}` : ''} at ${fmtTime(r.timestamp, true)}`;
        });
      }
      const readback = h('p', { class: 'hint', id: 'tag-readback', role: 'status' });
      const numeric = t.kind === 'float' || t.kind === 'int' || t.kind === 'bool';
      replace(detail,
        h('h2', { text: t.name }),
        h('p', { class: 'hint', text: t.description || 'No description.' }),
        h('dl', { class: 'kv' },
          h('dt', { text: 'Value' }), h('dd', {}, value),
          h('dt', { text: 'Quality' }), quality,
          h('dt', { text: 'Timestamp' }), stamp,
          h('dt', { text: 'Type' }), h('dd', { text: t.kind }),
          h('dt', { text: 'Writable' }), h('dd', { text: t.writable ? `yes, by ${t.write_role} and above` : 'no' }),
          t.limits ? h('dt', { text: 'Engineering limits' }) : null,
          t.limits ? h('dd', { id: 'tag-limits', text: `${limitsText(t.limits)}${t.units ? ` ${t.units}` : ''}` }) : null),
        h('h2', { text: 'Source' }),
        src ? h('dl', { class: 'kv', id: 'tag-source' },
          h('dt', { text: 'Device' }), h('dd', { text: `${src.device} (${protocolName(src.protocol)})` }),
          ...(src.iec104 ? [
            h('dt', { text: 'Point' }), h('dd', { text: `${src.iec104.point} at IOA ${src.iec104.ioa}` }),
            h('dt', { text: 'Command' }), h('dd', { text: src.iec104.command ? `${src.iec104.command} at IOA ${src.iec104.command_ioa}${src.iec104.select ? ', select before operate' : ', direct execute'}` : 'none' }),
          ] : src.dnp3 ? [
            h('dt', { text: 'Point' }), h('dd', { text: `${src.dnp3.point.replace('_', ' ')} ${src.dnp3.index}` }),
            h('dt', { text: 'Command' }), h('dd', { text: src.dnp3.command ? `${src.dnp3.command === 'crob' ? `CROB (${src.dnp3.op.replace('_', '/')})` : 'analog output'} at index ${src.dnp3.command_index}${src.dnp3.select ? ', select before operate' : ', direct operate'}` : 'none' }),
          ] : [
            h('dt', { text: 'Table' }), h('dd', { text: (src.table || '').replace('_', ' ') }),
            h('dt', { text: 'Address' }), h('dd', { text: `${src.address}${src.bit !== null && src.bit !== undefined ? ` bit ${src.bit}` : ''}` }),
            h('dt', { text: 'Word order' }), h('dd', { text: src.word_order }),
            h('dt', { text: 'Byte order' }), h('dd', { text: src.byte_order }),
          ]),
          h('dt', { text: 'Data type' }), h('dd', { text: src.data_type }),
          h('dt', { text: 'Scaling' }), h('dd', { text: `× ${src.scale} + ${src.offset}` }),
          h('dt', { text: 'Timestamp' }), h('dd', { id: 'tag-time-source', text: src.iec104 ? 'the station\'s time tag (CP56Time2a) where sent, else receive time' : src.dnp3 ? 'the outstation\'s event time where sent, else receive time' : src.time_tag ? `device clock ${src.time_tag}` : 'receive time' }))
          : h('p', { class: 'hint', id: 'tag-source', text: 'Derived by the server (device status, sequence or dispatch), not read from a device.' }),
        h('div', { class: 'btn-row' }, writeBtn,
          numeric ? h('a', { class: 'btn', id: 'tag-add-trend', href: `#/trends?pens=${enc(t.name)}`, text: 'Add to trend' }) : null),
        readback);
    }

    loadChildren('', tree);
    setFilter({});
    return () => {
      disposed = true;
      offWatch();
      offTags();
      binder.dispose();
      if (detailBinder) detailBinder.dispose();
    };
  },
};
