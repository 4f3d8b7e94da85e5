// Screen editor: administrators draw mimic screens of their own plant. A
// screen list (new, rename, copy, delete, export, import), a canvas with a
// 10 px snap grid where elements are placed from the palette, selected,
// moved, resized and deleted, with undo and redo, a properties form for the
// selected element whose tags are picked from the tag browser's search, and
// Save, which the server checks and keeps as a new version.

import { get, put, del, qs, enc } from '../api.js';
import { h, replace, field, select } from '../dom.js';
import { attempt, confirmDialog, formDialog, toast } from '../ui.js';
import { drawScreen } from './custom.js';
import { placement } from './network.js';

const GRID = 10;
const snap = (v) => Math.max(0, Math.round(v / GRID) * GRID);

/** What the palette places, with a sensible size and the fields it needs. */
const PALETTE = [
  ['text', 'Text', { w: 200, h: 40, text: 'Label', size: 16 }],
  ['line', 'Line / busbar', { w: 200, h: 10, busbar: false }],
  ['rect', 'Rectangle', { w: 200, h: 120, label: '' }],
  ['breaker', 'Breaker', { w: 150, h: 50, tag: '', label: 'Breaker' }],
  ['value', 'Value', { w: 180, h: 50, tag: '', label: '' }],
  ['bar', 'Bar', { w: 200, h: 40, tag: '', label: '', min: 0, max: 100 }],
  ['multistate', 'Multi-state', { w: 180, h: 50, tag: '', label: '', states: [{ value: 0, label: 'Off' }, { value: 1, label: 'On' }] }],
  ['button', 'Command button', { w: 180, h: 60, tag: '', label: 'Command', value: true }],
  ['trend', 'Small trend', { w: 320, h: 180, pens: [], span_s: 600, label: '' }],
  ['link', 'Link to screen', { w: 160, h: 36, screen: 'main', label: 'Open' }],
  ['panel', 'Panel diagram', { w: 660, h: 420, panel: '' }],
];

const NEEDS_TAG = new Set(['breaker', 'value', 'bar', 'multistate', 'button']);

/** A dialog that finds a tag by search (as the tag browser does) and resolves with it. */
export function pickTag(title, accept = () => true) {
  return new Promise((resolve) => {
    let chosen = null;
    const input = h('input', { type: 'search', id: 'pick-search', placeholder: 'Search names and descriptions', size: 32 });
    const list = h('ul', { class: 'pick-list', id: 'pick-list' });
    let timer = null;
    let dialog = null;
    const run = async () => {
      try {
        const r = await get(`/api/tags${qs({ search: input.value.trim(), limit: 50 })}`);
        const fit = r.tags.filter(accept);
        replace(list, fit.length ? fit.map((t) => h('li', {},
          h('button', {
            type: 'button', class: 'btn btn-small pick-tag', dataset: { tag: t.name },
            onclick: () => { chosen = t; dialog.close(); },
            text: `${t.name}${t.units ? ` (${t.units})` : ''}`,
          }), h('span', { class: 'hint', text: ` ${t.description}` })))
          : h('li', { class: 'empty', text: 'No tag fits.' }));
      } catch (e) {
        replace(list, h('li', { class: 'error', text: e.detail }));
      }
    };
    input.addEventListener('input', () => { clearTimeout(timer); timer = setTimeout(run, 200); });
    formDialog(title, (f) => {
      f.append(input, list);
      dialog = f.closest('dialog');
      run();
    }, { submitLabel: 'Close' }).then(() => resolve(chosen));
  });
}

export default {
  mount(el, ctx) {
    let screens = [];
    let screen = null; // the one being edited (a deep copy)
    let selected = -1;
    let undo = [];
    let redo = [];
    let dirty = false;
    let dispose = null;
    let panels = [];

    const picker = h('select', { id: 'editor-screens', 'aria-label': 'Screen to edit' });
    const canvas = h('div', { class: 'custom-canvas editor-canvas', id: 'editor-canvas', tabindex: '0' });
    const props = h('form', { class: 'editor-props', id: 'editor-props', 'aria-label': 'Properties of the selected element' });
    const status = h('p', { class: 'hint', id: 'editor-status', role: 'status' });
    const fileInput = h('input', { type: 'file', accept: 'application/json,.json', hidden: true, id: 'editor-import-file' });
    const btn = (id, text, onclick, cls = 'btn btn-small') => h('button', { type: 'button', class: cls, id, text, onclick });
    const undoBtn = btn('editor-undo', 'Undo', () => step(undo, redo));
    // Shown when the plant has a switching network (see loadList).
    const fromNetworkBtn = btn('editor-from-network', 'From network…', fromNetwork);
    fromNetworkBtn.hidden = true;
    const redoBtn = btn('editor-redo', 'Redo', () => step(redo, undo));
    el.append(h('h1', { class: 'screen-title', text: 'Screen editor' }),
      h('div', { class: 'card editor-bar' },
        h('div', { class: 'btn-row' }, field('Screen', picker),
          btn('editor-new', 'New…', newScreen), fromNetworkBtn, btn('editor-rename', 'Rename…', rename), btn('editor-copy', 'Copy…', copy),
          btn('editor-delete', 'Delete…', remove), btn('editor-export', 'Export', exportJson), btn('editor-import', 'Import…', () => fileInput.click()),
          undoBtn, redoBtn, btn('editor-save', 'Save', save, 'btn btn-primary'), fileInput),
        status),
      h('div', { class: 'editor-layout' },
        h('section', { class: 'card editor-palette', 'aria-label': 'Palette' }, h('h2', { text: 'Add' }),
          PALETTE.map(([type, text]) => h('button', { type: 'button', class: 'btn btn-small', dataset: { palette: type }, text, onclick: () => add(type) }))),
        h('section', { class: 'card editor-stage', 'aria-label': 'Canvas' }, h('div', { class: 'custom-scroll' }, canvas)),
        h('section', { class: 'card', 'aria-label': 'Properties' }, h('h2', { text: 'Properties' }), props)));

    // --- the screen list ------------------------------------------------------
    async function loadList(keep) {
      try {
        const cat = await get('/api/screens');
        screens = cat.screens.filter((x) => x.kind === 'custom').map((x) => ({ id: x.id.slice('custom:'.length), label: x.label }));
        panels = cat.screens.filter((x) => x.kind === 'panel').map((x) => x.panel);
        fromNetworkBtn.hidden = !cat.screens.some((x) => x.id === 'network' && x.kind === 'builtin');
      } catch (e) {
        status.textContent = `Cannot list the screens: ${e.detail}`;
        return;
      }
      fillPicker();
      const want = keep || (screen && screen.id) || (screens[0] && screens[0].id);
      if (want && screens.some((x) => x.id === want)) { picker.value = want; await open(want); } else if (!screens.length) { screen = null; draw(); }
    }
    /** The saved screens, and the one open if it is not saved yet (new, copied or imported). */
    function fillPicker() {
      const unsaved = screen && !screens.some((x) => x.id === screen.id);
      const options = screens.map((x) => h('option', { value: x.id, text: `${x.label} (${x.id})` }));
      if (unsaved) options.push(h('option', { value: screen.id, text: `${screen.name} (${screen.id}), not saved yet` }));
      replace(picker, options.length ? options : h('option', { value: '', text: 'No screens yet: New…' }));
      if (screen) picker.value = screen.id;
    }
    picker.addEventListener('change', async () => {
      if (dirty && !(await confirmDialog('Unsaved changes', 'Leave this screen without saving?', { submitLabel: 'Leave' }))) {
        picker.value = screen.id; return;
      }
      open(picker.value);
    });

    async function open(id) {
      try {
        screen = await get(`/api/screens/${enc(id)}`);
      } catch (e) {
        toast(`Open ${id}: ${e.detail}`, 'error');
        return;
      }
      undo = []; redo = []; selected = -1; dirty = false;
      draw();
      fillPicker();
    }

    async function askIdName(title, id = '', name = '') {
      const data = await formDialog(title, (f) => f.append(
        field('Id (lowercase letters, digits, - and _)', h('input', { name: 'id', required: true, pattern: '[a-z0-9][a-z0-9_\\-]{0,63}', value: id, id: 'editor-new-id' })),
        field('Name', h('input', { name: 'name', required: true, maxlength: 256, value: name, id: 'editor-new-name' }))), { submitLabel: 'OK' });
      return data && { id: data.get('id').trim(), name: data.get('name').trim() };
    }

    async function newScreen() {
      const r = await askIdName('New screen');
      if (!r) return;
      if (screens.some((x) => x.id === r.id)) { toast(`A screen "${r.id}" exists already.`, 'error'); return; }
      screen = { id: r.id, name: r.name, version: 0, width: 1200, height: 700, elements: [] };
      undo = []; redo = []; selected = -1; dirty = true;
      draw();
      status.textContent = `New screen "${r.name}": place elements, then Save.`;
      fillPicker();
    }

    /**
     * A new screen with the network screen's automatic layout: a line per
     * section, bound to it (coloured live), where the network screen draws
     * it. Saved as "network", it is the network screen's layout: moving a
     * line here moves its section there (docs/NETWORK.md).
     */
    async function fromNetwork() {
      let model;
      try { model = await get('/api/network'); } catch (e) { toast(`The network model: ${e.detail}`, 'error'); return; }
      const r = await askIdName('New screen from the network', 'network', 'Network layout');
      if (!r) return;
      if (screens.some((x) => x.id === r.id)) { toast(`A screen "${r.id}" exists already: open it, or delete it first.`, 'error'); return; }
      const { at, W, H, SEC_W, SEC_H } = placement({ ...model, layout: null });
      const elements = model.sections.map((x) => {
        const p = at.get(x.id);
        return { type: 'line', x: p.x, y: Math.max(0, p.y - SEC_H / 2), w: SEC_W, h: SEC_H, busbar: x.busbar, section_tag: x.state_tag };
      });
      if (elements.length > 2000) { toast(`The network has ${elements.length} sections; a screen holds at most 2000 elements.`, 'error'); return; }
      screen = { id: r.id, name: r.name, version: 0, width: Math.min(10000, Math.max(1200, W)), height: Math.min(10000, Math.max(700, H)), elements };
      undo = []; redo = []; selected = -1; dirty = true;
      draw();
      status.textContent = `New screen "${r.name}" from the network's automatic layout: move the sections' lines${r.id === 'network' ? ', then Save: the network screen draws its sections where this screen puts them' : ', then Save'}.`;
      fillPicker();
    }

    async function rename() {
      if (!screen) return;
      const data = await formDialog('Rename screen', (f) => f.append(field('Name', h('input', { name: 'name', required: true, maxlength: 256, value: screen.name }))), { submitLabel: 'Rename' });
      if (!data) return;
      change(() => { screen.name = data.get('name').trim(); });
    }

    async function copy() {
      if (!screen) return;
      const r = await askIdName('Copy screen', `${screen.id}-copy`.slice(0, 64), `${screen.name} (copy)`);
      if (!r) return;
      screen = { ...structuredClone(screen), id: r.id, name: r.name, version: 0 };
      undo = []; redo = []; selected = -1; dirty = true;
      draw();
      status.textContent = `Copy "${r.name}": Save to keep it.`;
      fillPicker();
    }

    async function remove() {
      if (!screen) return;
      if (!(await confirmDialog('Delete screen', `Delete the screen "${screen.name}" (${screen.id})? Groups lose access to it.`, { submitLabel: 'Delete' }))) return;
      if (screen.version > 0) {
        const ok = await attempt('Delete', () => del(`/api/screens/${enc(screen.id)}`));
        if (ok === undefined) return;
      }
      toast(`Screen "${screen.name}" deleted.`, 'ok');
      screen = null; dirty = false;
      await loadList();
      if (ctx.refreshScreens) ctx.refreshScreens();
    }

    function exportJson() {
      if (!screen) return;
      const blob = new Blob([JSON.stringify(screen, null, 2)], { type: 'application/json' });
      const a = h('a', { href: URL.createObjectURL(blob), download: `${screen.id}.json` });
      document.body.append(a);
      a.click();
      a.remove();
      setTimeout(() => URL.revokeObjectURL(a.href), 1000);
    }

    fileInput.addEventListener('change', async () => {
      const f = fileInput.files[0];
      fileInput.value = '';
      if (!f) return;
      let imported;
      try { imported = JSON.parse(await f.text()); } catch (e) { toast(`${f.name}: not JSON (${e.message})`, 'error'); return; }
      if (!imported || typeof imported.id !== 'string' || !Array.isArray(imported.elements)) { toast(`${f.name}: not a screen (needs id and elements)`, 'error'); return; }
      const existing = screens.find((x) => x.id === imported.id);
      let version = 0;
      if (existing) {
        try { version = (await get(`/api/screens/${enc(imported.id)}`)).version; } catch { version = 0; }
      }
      screen = { ...imported, version };
      undo = []; redo = []; selected = -1; dirty = true;
      draw();
      status.textContent = `Imported "${imported.name}" from ${f.name}: Save to keep it${existing ? ' (replaces the stored one)' : ''}.`;
      fillPicker();
    });

    async function save() {
      if (!screen) return;
      try {
        const saved = await put(`/api/screens/${enc(screen.id)}`, screen);
        screen = saved; dirty = false;
        status.textContent = `Saved "${saved.name}" as version ${saved.version}.`;
        toast(`Screen "${saved.name}" saved (version ${saved.version}).`, 'ok');
        await loadList(saved.id);
        if (ctx.refreshScreens) ctx.refreshScreens();
      } catch (e) {
        if (e.status === 409) toast(`Not saved: ${e.detail}. Reload the screen to see the other change.`, 'error');
        else toast(`Not saved: ${e.detail}`, 'error');
        status.textContent = `Not saved: ${e.detail}`;
      }
    }

    // --- editing ------------------------------------------------------------
    function change(f) {
      undo.push(JSON.stringify(screen));
      if (undo.length > 200) undo.shift();
      redo = [];
      f();
      dirty = true;
      draw();
    }
    function step(from, to) {
      if (!screen || !from.length) return;
      to.push(JSON.stringify(screen));
      screen = JSON.parse(from.pop());
      if (selected >= screen.elements.length) selected = -1;
      dirty = true;
      draw();
    }

    function add(type) {
      if (!screen) { toast('Create or open a screen first.', 'error'); return; }
      const [, , defaults] = PALETTE.find(([t]) => t === type);
      const n = screen.elements.length;
      const e = { type, x: snap(20 + (n % 10) * 20), y: snap(20 + (n % 10) * 20), ...structuredClone(defaults) };
      if (type === 'panel' && panels.length) e.panel = panels[0];
      change(() => { screen.elements.push(e); selected = screen.elements.length - 1; });
    }

    function removeSelected() {
      if (selected < 0) return;
      change(() => { screen.elements.splice(selected, 1); selected = -1; });
    }

    let drawGen = 0;
    const tagCache = new Map();
    async function draw() {
      const gen = ++drawGen;
      if (dispose) { dispose(); dispose = null; }
      undoBtn.disabled = !undo.length;
      redoBtn.disabled = !redo.length;
      if (!screen) { replace(canvas, h('p', { class: 'empty', text: 'No screen open.' })); replace(props); return; }
      const d = await drawScreen(canvas, screen, ctx.session, { editing: true, cache: tagCache, current: () => gen === drawGen });
      if (gen !== drawGen) { d(); return; }
      dispose = d;
      canvas.querySelectorAll('.el').forEach((box) => {
        const i = Number(box.dataset.elementIndex);
        box.classList.toggle('el-selected', i === selected);
        // A cover takes the pointer, so trends and buttons do not react while editing.
        const cover = h('div', { class: 'el-cover' });
        const grip = h('div', { class: 'el-grip', title: 'Drag to resize' });
        box.append(cover, grip);
        cover.addEventListener('pointerdown', (ev) => drag(ev, i, 'move'));
        grip.addEventListener('pointerdown', (ev) => drag(ev, i, 'size'));
      });
      drawProps();
    }

    function drag(ev, i, mode) {
      ev.preventDefault();
      ev.stopPropagation();
      if (selected !== i) {
        // Select without redrawing the canvas, so the box dragged below is the one on view.
        selected = i;
        canvas.querySelectorAll('.el').forEach((b) => b.classList.toggle('el-selected', Number(b.dataset.elementIndex) === i));
        drawProps();
      }
      const e0 = { ...screen.elements[i] };
      const x0 = ev.clientX;
      const y0 = ev.clientY;
      let moved = false;
      const box = canvas.querySelector(`[data-element-index="${i}"]`);
      const move = (m) => {
        const dx = m.clientX - x0;
        const dy = m.clientY - y0;
        if (!moved && Math.abs(dx) + Math.abs(dy) < 3) return;
        moved = true;
        if (box) {
          if (mode === 'move') { box.style.left = `${snap(e0.x + dx)}px`; box.style.top = `${snap(e0.y + dy)}px`; }
          else { box.style.width = `${Math.max(GRID, snap(e0.w + dx))}px`; box.style.height = `${Math.max(GRID, snap(e0.h + dy))}px`; }
        }
      };
      const up = (u) => {
        window.removeEventListener('pointermove', move);
        window.removeEventListener('pointerup', up);
        if (!moved) return;
        const dx = u.clientX - x0;
        const dy = u.clientY - y0;
        change(() => {
          const e = screen.elements[i];
          if (mode === 'move') {
            e.x = Math.min(screen.width - GRID, snap(e0.x + dx));
            e.y = Math.min(screen.height - GRID, snap(e0.y + dy));
          } else {
            e.w = Math.max(GRID, snap(e0.w + dx));
            e.h = Math.max(GRID, snap(e0.h + dy));
          }
        });
      };
      window.addEventListener('pointermove', move);
      window.addEventListener('pointerup', up);
    }

    canvas.addEventListener('pointerdown', (ev) => { if (ev.target === canvas && selected >= 0) { selected = -1; draw(); } });
    const onKey = (ev) => {
      if (!el.isConnected || ev.target.closest('input, textarea, select, dialog')) return;
      if ((ev.ctrlKey || ev.metaKey) && ev.key.toLowerCase() === 'z') { ev.preventDefault(); step(undo, redo); } else if ((ev.ctrlKey || ev.metaKey) && ev.key.toLowerCase() === 'y') { ev.preventDefault(); step(redo, undo); } else if ((ev.key === 'Delete' || ev.key === 'Backspace') && selected >= 0) { ev.preventDefault(); removeSelected(); }
    };
    document.addEventListener('keydown', onKey);

    // --- properties -----------------------------------------------------------
    function drawProps() {
      if (selected < 0 || !screen || !screen.elements[selected]) {
        replace(props, screen ? [
          h('p', { class: 'hint', text: 'Select an element, or add one from the palette.' }),
          h('div', { class: 'filters' },
            numberField('Canvas width', screen.width, (v) => { screen.width = v; }, 'editor-width'),
            numberField('Canvas height', screen.height, (v) => { screen.height = v; }, 'editor-height'))] : []);
        return;
      }
      const e = screen.elements[selected];
      const rows = [h('p', { class: 'hint', text: `${e.type} element ${selected}` }),
        h('div', { class: 'filters' }, ['x', 'y', 'w', 'h'].map((k) => numberField(k, e[k], (v) => { e[k] = v; }, `prop-${k}`)))];
      const text = (k, lab) => textField(lab, e[k] ?? '', (v) => { e[k] = v; }, `prop-${k}`);
      if (e.type === 'text') rows.push(text('text', 'Text'), numberField('Size (px)', e.size ?? 16, (v) => { e.size = v; }, 'prop-size'));
      if (e.type === 'line') {
        rows.push(h('label', { class: 'field field-inline' }, checkbox(e.busbar, (v) => { e.busbar = v; }), 'Busbar (thick)'));
        // Coloured live by a network section's state, as on the network screen.
        rows.push(h('div', { class: 'field' }, h('span', { class: 'field-label', text: 'Network section' }),
          h('span', { class: 'prop-tag', id: 'prop-section', text: e.section_tag || '(none: drawn in the wire colour)' }),
          h('button', { type: 'button', class: 'btn btn-small', id: 'prop-pick-section', text: 'Pick section…', onclick: async () => {
            const t = await pickTag('Network section for the line (its state tag)', (x) => x.kind === 'str' && /\.Sec\.[^.]+\.State$/.test(x.name));
            if (t) change(() => { e.section_tag = t.name; });
          } }),
          e.section_tag ? h('button', { type: 'button', class: 'btn btn-small', id: 'prop-clear-section', text: 'Clear', onclick: () => change(() => { delete e.section_tag; }) }) : null));
      }
      if (['rect', 'breaker', 'value', 'bar', 'multistate', 'button', 'trend', 'link'].includes(e.type)) rows.push(text('label', 'Label'));
      if (NEEDS_TAG.has(e.type)) {
        const accept = e.type === 'breaker' ? (t) => t.kind === 'bool'
          : e.type === 'bar' ? (t) => t.kind === 'float' || t.kind === 'int'
            : e.type === 'button' ? (t) => t.writable : () => true;
        rows.push(h('div', { class: 'field' }, h('span', { class: 'field-label', text: 'Tag' }),
          h('span', { class: 'prop-tag', id: 'prop-tag', text: e.tag || '(none)' }),
          h('button', { type: 'button', class: 'btn btn-small', id: 'prop-pick-tag', text: 'Pick tag…', onclick: async () => {
            const t = await pickTag(`Tag for the ${e.type}`, accept);
            if (t) change(() => { e.tag = t.name; if (e.type === 'button' && t.kind !== 'bool' && typeof e.value === 'boolean') e.value = 0; });
          } })));
      }
      if (e.type === 'value') rows.push(numberField('Decimals', e.digits ?? '', (v) => { e.digits = v; }, 'prop-digits', true), text('units', 'Units (blank: the tag\'s)'));
      if (e.type === 'value' || e.type === 'breaker') {
        const c = checkbox(e.time, (v) => { if (v) e.time = true; else delete e.time; });
        c.id = 'prop-time';
        rows.push(h('label', { class: 'field field-inline' }, c, 'Show the time stamp (to the millisecond)'));
      }
      if (e.type === 'bar') rows.push(numberField('Min', e.min, (v) => { e.min = v; }, 'prop-min'), numberField('Max', e.max, (v) => { e.max = v; }, 'prop-max'));
      if (e.type === 'multistate') {
        rows.push(textField('States (value=label, one per line)', (e.states || []).map((x) => `${x.value}=${x.label}`).join('\n'), (v) => {
          e.states = v.split('\n').map((l) => l.trim()).filter(Boolean).map((l) => {
            const [k, ...rest] = l.split('=');
            return { value: Number(k), label: rest.join('=').trim() };
          });
        }, 'prop-states', true));
      }
      if (e.type === 'button') {
        rows.push(textField('Value to write (true, false or a number)', String(e.value), (v) => {
          const t = v.trim();
          e.value = t === 'true' ? true : t === 'false' ? false : Number.isFinite(Number(t)) && t !== '' ? Number(t) : t;
        }, 'prop-value'));
      }
      if (e.type === 'trend') {
        rows.push(h('div', { class: 'field' }, h('span', { class: 'field-label', text: 'Pens' }),
          h('ul', { class: 'pen-list', id: 'prop-pens' }, (e.pens || []).map((p, k) => h('li', {}, p,
            h('button', { type: 'button', class: 'btn btn-small', 'aria-label': `Remove pen ${p}`, text: '×', onclick: () => change(() => { e.pens.splice(k, 1); }) })))),
          h('button', { type: 'button', class: 'btn btn-small', id: 'prop-add-pen', text: 'Add pen…', onclick: async () => {
            const t = await pickTag('Pen for the trend', (x) => x.kind === 'float' || x.kind === 'int' || x.kind === 'bool');
            if (t && !(e.pens || []).includes(t.name)) change(() => { e.pens = [...(e.pens || []), t.name]; });
          } })),
        numberField('Span (s)', e.span_s, (v) => { e.span_s = v; }, 'prop-span'));
      }
      if (e.type === 'link') rows.push(text('screen', 'Screen id (e.g. main, custom:other)'));
      if (e.type === 'panel') {
        const sel = select({ id: 'prop-panel' }, panels, e.panel);
        sel.addEventListener('change', () => change(() => { e.panel = sel.value; }));
        rows.push(field('Panel', sel));
      }
      rows.push(h('div', { class: 'btn-row' },
        h('button', { type: 'button', class: 'btn btn-small btn-danger', id: 'prop-delete', text: 'Delete element', onclick: removeSelected })));
      replace(props, rows);
    }

    function numberField(lab, value, set, id, optional = false) {
      const input = h('input', { type: 'number', id, value: value === undefined || value === null ? '' : String(value), step: 'any' });
      input.addEventListener('change', () => {
        if (optional && input.value === '') { change(() => set(undefined)); return; }
        const v = Number(input.value);
        if (!Number.isFinite(v)) { toast(`${lab}: not a number`, 'error'); return; }
        change(() => set(['x', 'y', 'w', 'h'].includes(lab) ? Math.round(v) : v));
      });
      return field(lab, input);
    }
    function textField(lab, value, set, id, multiline = false) {
      const input = multiline ? h('textarea', { id, rows: 4 }) : h('input', { type: 'text', id, maxlength: 256 });
      input.value = value;
      input.addEventListener('change', () => change(() => set(input.value)));
      return field(lab, input);
    }
    function checkbox(value, set) {
      const c = h('input', { type: 'checkbox', checked: !!value });
      c.addEventListener('change', () => change(() => set(c.checked)));
      return c;
    }

    loadList();
    return () => {
      document.removeEventListener('keydown', onKey);
      if (dispose) dispose();
    };
  },
};
