// The frame's footer: the live alarm list with a selection and a priority
// filter, the count shown, Ack Top, Ack All, Print and the horn's mute.

import { post } from '../api.js';
import { h, select } from '../dom.js';
import { roleAtLeast } from '../format.js';
import { live } from '../live.js';
import { attempt, toast } from '../ui.js';
import { beeper } from './beeper.js';
import { ALARM_HEADERS, drawAlarmRows, filterAlarms, sortAlarms } from './alarmtable.js';

export const PRIORITY_LEVELS = [['', 'Any priority'], ['200', '≥ 200'], ['400', '≥ 400'], ['600', '≥ 600'], ['800', '≥ 800']];

export class AlarmFooter {
  constructor(root, session) {
    this.root = root;
    this.session = session;
    this.known = null; // ids of unacknowledged alarms already heard
    this.selection = '';
    this.minPriority = '';
    this.build();
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
    const muteBtn = h('button', { type: 'button', class: 'btn btn-small', id: 'footer-mute', 'aria-pressed': String(beeper.muted) });
    const drawMute = () => {
      muteBtn.textContent = beeper.muted ? 'Horn muted' : 'Mute horn';
      muteBtn.setAttribute('aria-pressed', String(beeper.muted));
    };
    drawMute();
    muteBtn.addEventListener('click', () => { beeper.setMuted(!beeper.muted); drawMute(); });
    const buttons = [];
    if (canAck) {
      buttons.push(
        h('button', { type: 'button', class: 'btn btn-small', id: 'ack-top', onclick: () => this.ack('top'), text: 'Ack Top' }),
        h('button', { type: 'button', class: 'btn btn-small', id: 'ack-all', onclick: () => this.ack('all'), text: 'Ack All' }));
    }
    buttons.push(
      h('button', { type: 'button', class: 'btn btn-small', id: 'footer-print', onclick: () => this.print(), text: 'Print' }),
      muteBtn);
    this.tbody = h('tbody');
    this.root.replaceChildren(
      h('div', { class: 'footer-bar' },
        h('h2', { class: 'footer-title', text: 'Alarms' }), this.count, this.selSelect, this.prioSelect,
        h('div', { class: 'footer-buttons' }, buttons)),
      h('div', { class: 'footer-list' },
        h('table', { class: 'data alarms', id: 'footer-alarms' },
          h('thead', {}, h('tr', {}, ALARM_HEADERS.map((t) => h('th', { scope: 'col', text: t })))),
          this.tbody)));
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
    drawAlarmRows(this.tbody, shown);
    this.sound(list);
  }

  // Beeps once for every alarm that became unacknowledged since the last list.
  sound(list) {
    const now = new Set(list.filter((a) => !a.acked && a.active).map((a) => a.id));
    if (this.known) {
      const fresh = list.filter((a) => now.has(a.id) && !this.known.has(a.id));
      if (fresh.length) beeper.beep(Math.max(...fresh.map((a) => a.priority)));
    }
    this.known = now;
  }

  async ack(which) {
    const body = which === 'top' ? { top: true, filter: this.filter() } : { all: true, filter: this.filter() };
    const r = await attempt(which === 'top' ? 'Ack Top' : 'Ack All', () => post('/api/alarms/ack', body));
    if (r) toast(r.count ? `${r.count} alarm${r.count === 1 ? '' : 's'} acknowledged.` : 'Nothing to acknowledge.', 'ok');
  }

  print() {
    document.body.classList.add('print-alarms');
    const done = () => { document.body.classList.remove('print-alarms'); window.removeEventListener('afterprint', done); };
    window.addEventListener('afterprint', done);
    window.print();
    setTimeout(done, 1000);
  }

  dispose() {
    this.offWant();
    this.offAlarms();
  }
}
