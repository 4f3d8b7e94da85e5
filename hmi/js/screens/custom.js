// Screens users drew in the editor: drawing their elements, live. The same
// drawing serves the editor (without commands). Every label is text from a
// user: it is only ever set as textContent, never parsed as markup.

import { get, qs, enc } from '../api.js';
import { h, replace, s } from '../dom.js';
import { fmtTime, fmtValue, noteTags, qualityOf, roleAtLeast, showSample } from '../format.js';
import { Binder } from '../ui.js';
import { TrendChart, PEN_COLORS } from '../components/chart.js';
import { singleLine } from '../components/singleline.js';
import { STATE_CLASSES, levelClass, levelsOf, stateClass } from '../components/netstate.js';
import { devicesUnder, panelPrefix } from './common.js';
import { confirmedWrite } from './tags.js';

const TREND_RELOAD_MS = 5000;

/** Places `node` on the canvas at the element's box. */
function place(node, e) {
  node.style.left = `${e.x}px`;
  node.style.top = `${e.y}px`;
  node.style.width = `${e.w}px`;
  node.style.height = `${e.h}px`;
  return node;
}

/**
 * The time of a tag's sample, to the millisecond (the device's time stamp
 * where it sends one), the date in the tooltip.
 */
function timeOf(binder, tag) {
  const t = h('span', { class: 'el-time' });
  binder.on(tag, (smp) => {
    const ts = smp && smp.timestamp;
    const full = ts ? fmtTime(ts, true) : '';
    t.textContent = full ? full.slice(11) : '';
    t.title = full ? `time of the value: ${full}` : 'no value yet';
  });
  return t;
}

/**
 * A line bound to a network section (its state tag, NET.Sec.<id>.State):
 * coloured as the network screen colours the section, its state in words
 * in the tooltip (colour is never the only signal).
 */
function sectionColours(box, line, e, live) {
  const m = /\.Sec\.(.+)\.State$/.exec(e.section_tag);
  const section = m ? m[1] : e.section_tag;
  const net = live.network;
  line.classList.add('net-wire', net ? levelClass(net.model, net.levels, section) : 'net-lvl-0', 'net-unknown');
  box.dataset.section = section;
  live.binder.on(e.section_tag, (smp, connected) => {
    const q = qualityOf(smp, connected);
    const state = q.usable && smp ? String(smp.value) : 'UNKNOWN';
    line.classList.remove(...STATE_CLASSES);
    line.classList.add(stateClass(state));
    box.dataset.state = state;
    box.title = `Section ${section}: ${state}${q.reason ? ` (${q.reason})` : ''}`;
  });
}

/** An element's label: always a span (empty and hidden without text). */
const label = (text, cls = 'el-label') => h('span', { class: cls, text: text || '', hidden: !text });

/**
 * Draws element `e` (index `i`). `live` = { binder, session, tags (name ->
 * metadata), editing, cleanups }: in the editor, commands do nothing.
 */
export function drawElement(e, i, live) {
  const box = h('div', { class: ['el', `el-${e.type}`], dataset: { elementType: e.type, elementIndex: String(i) } });
  place(box, e);
  const { binder } = live;
  switch (e.type) {
    case 'text': {
      box.textContent = e.text;
      if (e.size) box.style.fontSize = `${e.size}px`;
      break;
    }
    case 'line': {
      // Along the longer side of its box: a busbar or a wire, horizontal or vertical.
      const horizontal = e.w >= e.h;
      const svg = s('svg', { width: e.w, height: e.h, class: 'el-line-svg', 'aria-hidden': 'true' });
      const line = s('line', horizontal
        ? { x1: 0, y1: e.h / 2, x2: e.w, y2: e.h / 2, class: e.busbar ? 'sl-bus' : 'sl-wire' }
        : { x1: e.w / 2, y1: 0, x2: e.w / 2, y2: e.h, class: e.busbar ? 'sl-bus' : 'sl-wire' });
      svg.append(line);
      box.append(svg);
      if (e.section_tag) sectionColours(box, line, e, live);
      break;
    }
    case 'rect': {
      box.append(label(e.label, 'el-rect-label'));
      break;
    }
    case 'breaker': {
      const sym = h('span', { class: 'el-breaker-symbol', 'aria-hidden': 'true' });
      const st = h('span', { class: 'bk-text' });
      const text = h('span', { class: 'el-breaker-text' }, label(e.label), st);
      if (e.time) text.append(timeOf(binder, e.tag));
      box.append(sym, text);
      binder.on(e.tag, (smp, connected) => {
        const q = qualityOf(smp, connected);
        const known = q.usable && typeof smp.value === 'boolean';
        const cls = !known ? 'bk-unknown' : smp.value ? 'bk-closed' : 'bk-open';
        st.textContent = !known ? '? UNKNOWN' : smp.value ? 'CLOSED' : 'OPEN';
        st.className = `bk-text ${cls}`;
        box.className = `el el-breaker ${cls}`;
        box.title = `${e.label || e.tag}: ${st.textContent}${q.reason ? ` (${q.reason})` : ''}`;
      });
      break;
    }
    case 'value': {
      const v = h('span', { class: 'value el-value-text' });
      box.append(label(e.label), v);
      const meta = live.tags.get(e.tag);
      binder.show(v, e.tag, { units: e.units ?? (meta ? meta.units : ''), digits: e.digits ?? undefined, kind: meta ? meta.kind : undefined });
      if (e.time) box.append(timeOf(binder, e.tag));
      break;
    }
    case 'bar': {
      const fill = h('span', { class: 'el-bar-fill' });
      const text = h('span', { class: 'value' });
      // A meter always has a value: the minimum, said to be unknown, until a usable sample comes.
      const track = h('span', { class: 'el-bar-track', role: 'meter', 'aria-label': e.label || e.tag, 'aria-valuemin': e.min, 'aria-valuemax': e.max, 'aria-valuenow': e.min, 'aria-valuetext': 'unknown' }, fill);
      box.append(label(e.label), track, text);
      const meta = live.tags.get(e.tag);
      binder.on(e.tag, (smp, connected) => {
        showSample(text, smp, { units: meta ? meta.units : '', kind: meta ? meta.kind : undefined, tag: e.tag, live: connected });
        const q = qualityOf(smp, connected);
        const ok = q.usable && typeof smp.value === 'number';
        const frac = ok ? Math.min(1, Math.max(0, (smp.value - e.min) / (e.max - e.min))) : 0;
        fill.style.width = `${frac * 100}%`;
        fill.className = `el-bar-fill${ok ? '' : ' q-bad'}`;
        track.setAttribute('aria-valuenow', String(ok ? Math.min(e.max, Math.max(e.min, smp.value)) : e.min));
        track.setAttribute('aria-valuetext', ok ? text.textContent : `unknown${q.reason ? `: ${q.reason}` : ''}`);
      });
      break;
    }
    case 'multistate': {
      const v = h('span', { class: 'el-state' });
      box.append(label(e.label), v);
      binder.on(e.tag, (smp, connected) => {
        const q = qualityOf(smp, connected);
        if (!q.usable || smp.value === undefined || smp.value === null) {
          v.textContent = '? UNKNOWN'; v.className = 'el-state q-bad'; v.title = q.reason; return;
        }
        const n = typeof smp.value === 'boolean' ? Number(smp.value) : Number(smp.value);
        const st = (e.states || []).find((x) => x.value === n);
        v.textContent = st ? st.label : `? ${fmtValue(smp.value)}`;
        v.className = `el-state ${st ? 'q-good' : 'q-uncertain'}`;
        v.title = st ? `${st.label} (${n})` : 'a value without a label';
      });
      break;
    }
    case 'button': {
      const meta = live.tags.get(e.tag);
      const may = meta && meta.writable && meta.write_role && roleAtLeast(live.session.role, meta.write_role);
      const btn = h('button', { type: 'button', class: 'btn btn-primary el-button', text: e.label, disabled: !may && !live.editing });
      const out = h('span', { class: 'el-readback', role: 'status' });
      if (!may) btn.title = meta ? `writing ${e.tag} needs the ${meta.write_role} role` : `${e.tag} is not readable for you`;
      btn.addEventListener('click', async () => {
        if (live.editing || !may) return;
        const r = await confirmedWrite(meta, e.value);
        if (r) out.textContent = `✓ ${fmtValue(r.value, meta.decimals ?? undefined)}${meta.units ? ` ${meta.units}` : ''}`;
      });
      box.append(btn, out);
      break;
    }
    case 'trend': {
      const canvas = h('canvas', { class: 'el-trend-canvas' });
      box.append(label(e.label), canvas);
      const chart = new TrendChart(canvas);
      const pens = (e.pens || []).map((tag, k) => ({ tag, color: PEN_COLORS[k % PEN_COLORS.length], units: (live.tags.get(tag) || {}).units || '' }));
      const load = async () => {
        const to = Date.now();
        const from = to - (e.span_s || 600) * 1000;
        try {
          const r = await get(`/api/trends${qs({ tags: pens.map((p) => p.tag).join(','), from, to, points: Math.max(20, Math.min(500, e.w)) })}`);
          chart.setData(pens.map((p) => ({ ...p, buckets: ((r.series || []).find((x) => x.tag === p.tag) || {}).buckets || [] })), from, to);
        } catch { /* shown empty; the next reload tries again */ }
      };
      if (pens.length && !live.editing) {
        load();
        const t = setInterval(load, TREND_RELOAD_MS);
        live.cleanups.push(() => clearInterval(t));
      }
      live.cleanups.push(() => chart.dispose());
      break;
    }
    case 'link': {
      box.append(h('a', { class: 'btn el-link', href: live.editing ? '#' : `#/${e.screen}`, text: e.label }));
      break;
    }
    case 'panel': {
      const holder = h('div', { class: 'el-panel-body' }, h('p', { class: 'loading', text: `Panel ${e.panel}…` }));
      box.append(holder);
      (async () => {
        try {
          const p = await get(`/api/panels/${enc(e.panel)}`);
          const prefix = panelPrefix(p);
          const devices = await devicesUnder(prefix).catch(() => []);
          const diagram = singleLine(binder, { prefix, title: p.name, zones: p.zones, devices });
          diagram.panelStatus(p);
          replace(holder, diagram);
          // The panel's mode and isolated zones, as on its own screen.
          const t = setInterval(() => {
            if (!holder.isConnected) { clearInterval(t); return; } // the screen was left meanwhile
            get(`/api/panels/${enc(e.panel)}`).then((st) => diagram.panelStatus(st)).catch(() => {});
          }, 2000);
          live.cleanups.push(() => clearInterval(t));
        } catch (err) {
          replace(holder, h('p', { class: 'error', text: `Panel ${e.panel}: ${err.detail || err.message}` }));
        }
      })();
      break;
    }
    default:
      box.append(h('span', { class: 'error', text: `unknown element "${e.type}"` }));
  }
  return box;
}

/** The metadata of the tags a screen's elements use (those the caller may read). */
export async function tagsOf(screen, cache = new Map()) {
  const names = new Set();
  for (const e of screen.elements || []) {
    if (e.tag) names.add(e.tag);
    for (const p of e.pens || []) names.add(p);
  }
  await Promise.all([...names].filter((n) => !cache.has(n)).map(async (n) => {
    try { cache.set(n, await get(`/api/tags/${enc(n)}`)); } catch { /* not readable: drawn as unknown */ }
  }));
  noteTags([...cache.values()]);
  return cache;
}

/** Draws a whole screen into a canvas element; returns a disposer. */
export async function drawScreen(canvas, screen, session, { editing = false, cache, current = () => true } = {}) {
  const tags = await tagsOf(screen, cache);
  // A newer drawing started meanwhile: leave the canvas to it.
  if (!current()) return () => {};
  // Lines bound to network sections take their voltage level's colour from the model.
  let network = null;
  if ((screen.elements || []).some((e) => e.type === 'line' && e.section_tag)) {
    try {
      const model = await get('/api/network');
      network = { model, levels: levelsOf(model) };
    } catch { /* no network, or not readable: the lines use the first level's colour */ }
    if (!current()) return () => {};
  }
  const binder = new Binder();
  const cleanups = [];
  canvas.style.width = `${screen.width}px`;
  canvas.style.height = `${screen.height}px`;
  replace(canvas, (screen.elements || []).map((e, i) => drawElement(e, i, { binder, session, tags, editing, cleanups, network })));
  return () => { binder.dispose(); for (const c of cleanups) c(); };
}

/** The screen `custom:<id>`. */
export function customScreen(id) {
  return {
    mount(el, ctx) {
      let dispose = null;
      let gone = false;
      const title = h('h1', { class: 'screen-title', text: id });
      const canvas = h('div', { class: 'custom-canvas', id: 'custom-screen' });
      el.append(title, h('div', { class: 'custom-scroll' }, canvas));
      (async () => {
        try {
          const screen = await get(`/api/screens/${enc(id)}`);
          if (gone) return;
          title.textContent = screen.name;
          document.title = `gridscada — ${screen.name}`;
          dispose = await drawScreen(canvas, screen, ctx.session);
          if (gone) dispose();
        } catch (e) {
          replace(canvas, h('p', { class: 'error', text: `Cannot open the screen: ${e.detail}` }));
        }
      })();
      return () => { gone = true; if (dispose) dispose(); };
    },
  };
}
