// The frame's footer: the live alarm list with a selection and a priority
// filter, the count shown, Ack Top, Ack All, Print and the horn's mute.

import { post } from '../api.js';
import { h, select } from '../dom.js';
import { fmtTime, roleAtLeast } from '../format.js';
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
    this.shown = shown;
    drawAlarmRows(this.tbody, shown);
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
    document.body.classList.add('print-alarms');
    const done = () => { document.body.classList.remove('print-alarms'); window.removeEventListener('afterprint', done); };
    window.addEventListener('afterprint', done);
    window.print();
    setTimeout(done, 1000);
  }

  dispose() {
    this.offWant();
    this.offAlarms();
    this.offHorn();
    clearInterval(this.muteTimer);
    beeper.setAlarms([]);
  }
}
