// Shared UI pieces: messages to the operator, modal dialogs, and the binder
// that keeps elements in step with live tags.

import { h } from './dom.js';
import { dateFormat, datePattern, fmtDate, onDecimals, showSample } from './format.js';
import { live } from './live.js';

/** Shows a message; errors stay until dismissed, others fade after a while. */
export function toast(text, kind = 'info') {
  const box = document.getElementById('toasts');
  const close = h('button', { type: 'button', class: 'toast-close', 'aria-label': 'Dismiss message', text: '×' });
  const t = h('div', { class: ['toast', `toast-${kind}`], role: kind === 'error' ? 'alert' : 'status' },
    h('span', { class: 'toast-text', text }), close);
  close.addEventListener('click', () => t.remove());
  box.append(t);
  if (kind !== 'error') setTimeout(() => t.remove(), 5000);
  else setTimeout(() => t.remove(), 20000);
  return t;
}

/** Runs an API action and shows its error's detail to the operator. */
export async function attempt(what, f) {
  try {
    return await f();
  } catch (e) {
    toast(`${what}: ${e.detail || e.message}`, 'error');
    return undefined;
  }
}

/**
 * A modal dialog with a form. `build(form)` adds the fields; resolves with
 * the FormData on submit, or null on cancel. Uses <dialog> so focus is trapped
 * and Escape cancels.
 */
export function formDialog(title, build, { submitLabel = 'OK', danger = false } = {}) {
  return new Promise((resolve) => {
    const form = h('form', { method: 'dialog', class: 'dialog-form' });
    const dlg = h('dialog', { class: 'dialog', 'aria-label': title }, h('h2', { text: title }), form);
    build(form);
    const cancel = h('button', { type: 'button', class: 'btn', text: 'Cancel' });
    const ok = h('button', { type: 'submit', class: ['btn', danger ? 'btn-danger' : 'btn-primary'], text: submitLabel });
    form.append(h('div', { class: 'dialog-buttons' }, cancel, ok));
    let result = null;
    cancel.addEventListener('click', () => dlg.close());
    form.addEventListener('submit', (ev) => {
      ev.preventDefault();
      if (!form.reportValidity()) return;
      result = new FormData(form);
      dlg.close();
    });
    dlg.addEventListener('close', () => { dlg.remove(); resolve(result); });
    document.body.append(dlg);
    dlg.showModal();
    const first = form.querySelector('input, select, textarea');
    if (first) first.focus();
  });
}

/** A yes/no confirmation; resolves true on confirm. */
export async function confirmDialog(title, message, { submitLabel = 'Confirm', danger = true } = {}) {
  const r = await formDialog(title, (f) => f.append(h('p', { text: message })), { submitLabel, danger });
  return r !== null;
}

/**
 * Keeps elements in step with live tags. `show(el, tag, opts)` renders a
 * sample with its quality; `on(tag, f)` calls f(sample, connected) on change.
 * Everything is redrawn when the connection drops or returns, so values
 * show as not live while disconnected.
 */
export class Binder {
  constructor() {
    this.handlers = new Map(); // tag -> [f]
    this.offTags = live.onTags((names, snapshot) => this.update(snapshot ? null : names));
    this.offStatus = live.onStatus(() => this.update(null));
    // Values drawn before their tags' decimals were read are drawn again with them.
    this.offDecimals = onDecimals(() => this.update(null));
    // The tags bound here are subscribed as one interest, re-sent once per batch of bindings.
    this.interest = { tags: [] };
    this.offWant = live.want(this.interest);
    this.pending = false;
  }

  on(tag, f) {
    if (!this.handlers.has(tag)) {
      this.handlers.set(tag, []);
      this.interest.tags.push(tag);
      if (!this.pending) {
        this.pending = true;
        queueMicrotask(() => { this.pending = false; live.sendSubscription(); });
      }
    }
    this.handlers.get(tag).push(f);
    f(live.get(tag), live.connected);
    return this;
  }

  sample(tag) { return live.get(tag); }

  show(el, tag, opts = {}) {
    return this.on(tag, (sample, connected) => showSample(el, sample, { tag, ...opts, live: connected }));
  }

  update(names) {
    const list = names || [...this.handlers.keys()];
    for (const n of list) {
      const fs = this.handlers.get(n);
      if (fs) for (const f of fs) f(live.get(n), live.connected);
    }
  }

  dispose() {
    this.offTags();
    this.offStatus();
    this.offDecimals();
    this.offWant();
    this.handlers.clear();
  }
}

/** A value element bound to a tag. */
export function valueEl(binder, tag, opts = {}) {
  const el = h('span', { class: 'value' });
  binder.show(el, tag, opts);
  return el;
}

/** A date field typed in the plant's order (`[hmi] date_format`): a date input would follow the browser's locale. */
export function dateInput(attrs, date) {
  return h('input', {
    type: 'text', size: 10, inputmode: 'numeric', placeholder: dateFormat(), pattern: datePattern(), title: `Date, ${dateFormat()}`,
    value: date ? fmtDate(date) : '', ...attrs,
  });
}
