// The frame's footer: the live alarm list with a selection and a priority
// filter, the count shown, Ack Top, Ack All, Print and the horn's mute.
// Its height is dragged (or set with the arrow keys) on its top edge and
// kept for the session; on a small screen, and on request, it shows the
// alarm counts by priority per area instead of rows.

import { post } from '../api.js';
import { h, select } from '../dom.js';
import { fmtTime, roleAtLeast } from '../format.js';
import { live } from '../live.js';
import { attempt, toast } from '../ui.js';
import { beeper } from './beeper.js';
import { ALARM_HEADERS, drawAlarmRows, filterAlarms, sortAlarms, summarize, summaryTable } from './alarmtable.js';

const HEIGHT_KEY = 'gridscada.footer.height';
const VIEW_KEY = 'gridscada.footer.view';
const MIN_H = 64;
/** A phone or a small tablet: the footer shows the summary per area. */
const COMPACT = '(max-width: 700px)';
/** The footer's height by default: on a phone, the bar and a few areas, so the process comes first. */
const DEFAULT_H = 150;
const PHONE_H = 120;

/**
 * Rows the footer draws: the top of the list, in its order (unacknowledged,
 * active, priority, newest). In a flood the rest are counted, and the
 * Alarms screen pages through them.
 */
export const FOOTER_ROWS = 100;

export const PRIORITY_LEVELS = [['', 'Any priority'], ['200', '≥ 200'], ['400', '≥ 400'], ['600', '≥ 600'], ['800', '≥ 800']];

export class AlarmFooter {
  constructor(root, session) {
    this.root = root;
    this.session = session;
    this.known = null; // ids of unacknowledged alarms already heard
    this.printing = false; // every row drawn, for the printout
    this.selection = '';
    this.minPriority = '';
    this.compact = window.matchMedia(COMPACT);
    this.view = sessionStorage.getItem(VIEW_KEY) || '';
    this.screen = '';
    this.build();
    this.applyHeight(Number(sessionStorage.getItem(HEIGHT_KEY)) || null);
    this.onMedia = () => { this.applyHeight(this.height); this.draw(live.alarms); };
    this.compact.addEventListener('change', this.onMedia);
    this.onResize = () => this.applyHeight(this.height);
    window.addEventListener('resize', this.onResize);
    this.root.dataset.horn = beeper.state;
    this.offWant = live.want({ alarms: true });
    this.offAlarms = live.onAlarms((list) => this.draw(list));
    this.draw(live.alarms);
  }

  build() {
    const canAck = roleAtLeast(this.session.role, 'operator');
    this.selSelect = select({ id: 'footer-selection', 'aria-label': 'Alarm selection filter' }, [['', 'All selections']], '');
    this.prioSelect = select({ id: 'footer-priority', 'aria-label': 'Alarm priority filter' }, PRIORITY_LEVELS, '');
    this.count = h('span', { class: 'alarm-count', id: 'footer-count', role: 'status' });
    this.selSelect.addEventListener('change', () => { this.selection = this.selSelect.value; this.draw(live.alarms); });
    this.prioSelect.addEventListener('change', () => { this.minPriority = this.prioSelect.value; this.draw(live.alarms); });
    // The horn: Silence quiets the alarms sounding now; Mute quiets it for a while, for this session.
    beeper.setUser(this.session.user);
    const silenceBtn = h('button', { type: 'button', class: 'btn btn-small', id: 'footer-silence', text: 'Silence', title: 'Silence the horn for the alarms sounding now (a new alarm sounds again)' });
    const muteBtn = h('button', { type: 'button', class: 'btn btn-small', id: 'footer-mute', 'aria-pressed': String(beeper.muted) });
    const drawMute = (state = beeper.state) => {
      const until = beeper.mutedUntil;
      muteBtn.textContent = until ? `Horn muted to ${fmtTime(until).slice(11, 16)}` : 'Mute horn';
      muteBtn.title = until ? 'Muted for this session until then; press to unmute' : 'Mute the horn for 15 minutes (this session only)';
      muteBtn.setAttribute('aria-pressed', String(!!until));
      silenceBtn.disabled = state !== 'sounding';
      this.root.dataset.horn = state;
      this.root.dataset.hornBeeps = String(beeper.beeps);
    };
    this.offHorn = beeper.onChange(drawMute);
    // The mute ends by itself: redraw when it does.
    this.muteTimer = setInterval(() => drawMute(), 5000);
    muteBtn.addEventListener('click', () => { beeper.setMuted(!beeper.muted); });
    silenceBtn.addEventListener('click', () => beeper.silence());
    const buttons = [];
    if (canAck) {
      buttons.push(
        h('button', { type: 'button', class: 'btn btn-small', id: 'ack-top', onclick: () => this.ack('top'), text: 'Ack Top' }),
        h('button', { type: 'button', class: 'btn btn-small', id: 'ack-all', onclick: () => this.ack('all'), text: 'Ack All' }));
    }
    buttons.push(
      h('button', { type: 'button', class: 'btn btn-small', id: 'footer-print', onclick: () => this.print(), text: 'Print' }),
      silenceBtn, muteBtn);
    this.viewBtn = h('button', { type: 'button', class: 'btn btn-small', id: 'footer-view', 'aria-pressed': 'false', text: 'By area',
      title: 'Show the alarm counts by priority for each area instead of rows' });
    this.viewBtn.addEventListener('click', () => {
      this.view = this.summaryShown() ? 'rows' : 'summary';
      sessionStorage.setItem(VIEW_KEY, this.view);
      this.draw(live.alarms);
    });
    buttons.unshift(this.viewBtn);
    // The top edge: drag it, or focus it and use the arrow keys.
    this.grip = h('div', { class: 'footer-resize', id: 'footer-resize', role: 'separator', tabindex: '0', 'aria-orientation': 'horizontal',
      'aria-label': 'Resize the alarm list', 'aria-controls': 'alarm-footer', title: 'Drag to resize the alarm list (or use the up and down arrow keys)' });
    this.wireGrip();
    this.tbody = h('tbody');
    // The lists scroll: reachable from the keyboard.
    this.list = h('div', { class: 'footer-list', tabindex: '0', role: 'group', 'aria-label': 'Alarm rows' },
      h('table', { class: 'data alarms', id: 'footer-alarms' },
        h('thead', {}, h('tr', {}, ALARM_HEADERS.map((t) => h('th', { scope: 'col', text: t })))),
        this.tbody));
    this.summary = h('div', { class: 'footer-list footer-summary', id: 'footer-summary', tabindex: '0', role: 'group', 'aria-label': 'Alarms by area', hidden: true });
    this.root.replaceChildren(this.grip,
      this.bar = h('div', { class: 'footer-bar' },
        h('h2', { class: 'footer-title', text: 'Alarms' }), this.count, this.selSelect, this.prioSelect,
        h('div', { class: 'footer-buttons' }, buttons)),
      this.list, this.summary);
  }

  /** The summary per area is shown on a small screen unless rows were asked for, and elsewhere on request. */
  summaryShown() {
    return this.view === 'summary' || (this.compact.matches && this.view !== 'rows');
  }

  /** On a phone the alarm screen is itself the list: the footer keeps only its bar there. */
  barOnly() {
    return this.compact.matches && this.screen === 'alarms';
  }

  /** Tells the footer which screen is shown. */
  setScreen(id) {
    const was = this.barOnly();
    this.screen = id;
    if (was !== this.barOnly()) { this.applyHeight(this.height); this.draw(live.alarms); }
  }

  maxHeight() { return Math.max(MIN_H, Math.round(window.innerHeight * 0.8)); }

  /** Sets the footer's height (null: the default for the screen's size), kept within the window. */
  applyHeight(px) {
    this.height = px;
    const def = this.compact.matches ? PHONE_H : DEFAULT_H;
    const wanted = this.barOnly() ? this.bar.getBoundingClientRect().height + 4 : px || def;
    const hgt = Math.round(Math.min(this.maxHeight(), Math.max(this.barOnly() ? 0 : MIN_H, wanted)));
    document.documentElement.style.setProperty('--footer-h', `${hgt}px`);
    this.grip.setAttribute('aria-valuenow', String(hgt));
    this.grip.setAttribute('aria-valuemin', String(MIN_H));
    this.grip.setAttribute('aria-valuemax', String(this.maxHeight()));
    this.grip.setAttribute('aria-valuetext', `${hgt} pixels high`);
    return hgt;
  }

  setHeight(px) {
    const hgt = this.applyHeight(px);
    this.height = hgt;
    sessionStorage.setItem(HEIGHT_KEY, String(hgt));
  }

  wireGrip() {
    const g = this.grip;
    let drag = null;
    g.addEventListener('pointerdown', (e) => {
      e.preventDefault();
      g.setPointerCapture(e.pointerId);
      drag = { y: e.clientY, h: this.root.getBoundingClientRect().height };
      this.root.classList.add('resizing');
    });
    g.addEventListener('pointermove', (e) => {
      if (!drag) return;
      this.applyHeight(drag.h + (drag.y - e.clientY));
    });
    const end = (e) => {
      if (!drag) return;
      drag = null;
      this.root.classList.remove('resizing');
      if (g.hasPointerCapture(e.pointerId)) g.releasePointerCapture(e.pointerId);
      this.setHeight(this.root.getBoundingClientRect().height);
    };
    g.addEventListener('pointerup', end);
    g.addEventListener('pointercancel', end);
    g.addEventListener('keydown', (e) => {
      const cur = this.root.getBoundingClientRect().height;
      const k = { ArrowUp: 20, ArrowDown: -20, PageUp: 100, PageDown: -100 }[e.key];
      if (k) { e.preventDefault(); this.setHeight(cur + k); }
      if (e.key === 'Home') { e.preventDefault(); this.setHeight(this.maxHeight()); }
      if (e.key === 'End') { e.preventDefault(); this.setHeight(MIN_H); }
    });
  }

  filter() {
    return { selection: this.selection || undefined, min_priority: this.minPriority ? Number(this.minPriority) : undefined };
  }

  draw(list) {
    // Selections offered are those present now, plus the chosen one.
    const sels = [...new Set(list.map((a) => a.selection).concat(this.selection ? [this.selection] : []))].sort();
    const current = this.selSelect.value;
    if (this.selSelect.options.length !== sels.length + 1 || sels.some((s, i) => this.selSelect.options[i + 1].value !== s)) {
      this.selSelect.replaceChildren(h('option', { value: '', text: 'All selections' }),
        ...sels.map((s) => h('option', { value: s, selected: s === current, text: s })));
    }
    const shown = sortAlarms(filterAlarms(list, { selection: this.selection, minPriority: Number(this.minPriority) || 0 }));
    const unacked = shown.filter((a) => !a.acked).length;
    this.count.textContent = `${shown.length} shown${shown.length !== list.length ? ` of ${list.length}` : ''}, ${unacked} unacked`;
    this.root.classList.toggle('has-unacked', list.some((a) => !a.acked));
    this.shown = shown;
    drawAlarmRows(this.tbody, shown, {
      // The printout is the whole list shown, not the top the footer draws.
      limit: this.printing ? Infinity : FOOTER_ROWS,
      more: () => [` below these ${FOOTER_ROWS}: `, h('a', { href: '#/alarms', text: 'open the Alarms screen' }), ' to page through them.'],
    });
    // The summary counts every standing alarm per area, whatever the filter.
    const summary = this.summaryShown();
    this.list.hidden = summary || this.barOnly();
    this.summary.hidden = !summary || this.barOnly();
    this.root.classList.toggle('footer-compact', summary);
    this.viewBtn.setAttribute('aria-pressed', String(summary));
    // Redrawn only when a count or the area chosen changed (a focused area button keeps its focus).
    const key = summary ? JSON.stringify([summarize(list), this.selection]) : '';
    if (summary && key !== this.summaryKey) {
      this.summary.replaceChildren(summaryTable(list, { id: 'footer-summary-table', current: this.selection, onPick: (sel) => {
        this.selection = sel;
        this.selSelect.value = sel;
        this.view = 'rows';
        sessionStorage.setItem(VIEW_KEY, this.view);
        this.draw(live.alarms);
      } }));
    }
    this.summaryKey = key;
    this.sound(list);
  }

  // The horn sounds while any active alarm is unacknowledged and not silenced.
  sound(list) {
    beeper.setAlarms(list.filter((a) => !a.acked && a.active).map((a) => ({ id: a.id, priority: a.priority })));
  }

  async ack(which) {
    if (which === 'top') {
      // Exactly the row shown at the top (the order is sortAlarms', in one place):
      // the first unacknowledged one, by its id.
      const top = (this.shown || []).find((a) => !a.acked);
      if (!top) { toast('Nothing to acknowledge.', 'ok'); return; }
      const r = await attempt('Ack Top', () => post('/api/alarms/ack', { ids: [top.id] }));
      if (r) toast(`Acknowledged: ${top.message}`, 'ok');
      return;
    }
    const r = await attempt('Ack All', () => post('/api/alarms/ack', { all: true, filter: this.filter() }));
    if (r) toast(r.count ? `${r.count} alarm${r.count === 1 ? '' : 's'} acknowledged.` : 'Nothing to acknowledge.', 'ok');
  }

  print() {
    this.printing = true;
    this.draw(live.alarms);
    document.body.classList.add('print-alarms');
    const done = () => {
      if (!this.printing) return;
      this.printing = false;
      document.body.classList.remove('print-alarms');
      window.removeEventListener('afterprint', done);
      this.draw(live.alarms);
    };
    window.addEventListener('afterprint', done);
    window.print();
    setTimeout(done, 1000);
  }

  dispose() {
    this.offWant();
    this.offAlarms();
    this.offHorn();
    clearInterval(this.muteTimer);
    this.compact.removeEventListener('change', this.onMedia);
    window.removeEventListener('resize', this.onResize);
    beeper.setAlarms([]);
  }
}
