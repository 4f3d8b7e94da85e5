// Login: the only screen of an anonymous visitor (shown as Guest).

import { post } from '../api.js';
import { h } from '../dom.js';

export default {
  mount(el, ctx) {
    const user = h('input', { id: 'login-user', name: 'username', autocomplete: 'username', required: true });
    const pass = h('input', { id: 'login-password', name: 'password', type: 'password', autocomplete: 'current-password', required: true });
    const msg = h('p', { class: 'form-error', id: 'login-error', role: 'alert' });
    const btn = h('button', { type: 'submit', class: 'btn btn-primary', id: 'login-submit', text: 'Log in' });
    const form = h('form', { class: 'login-form', 'aria-labelledby': 'login-title' },
      h('h1', { id: 'login-title', text: 'Log in' }),
      h('p', { class: 'hint', text: 'You are Guest until you log in.' }),
      h('label', { class: 'field' }, h('span', { class: 'field-label', text: 'User name' }), user),
      h('label', { class: 'field' }, h('span', { class: 'field-label', text: 'Password' }), pass),
      msg, btn);
    form.addEventListener('submit', async (ev) => {
      ev.preventDefault();
      msg.textContent = '';
      btn.disabled = true;
      try {
        await post('/api/session', { username: user.value, password: pass.value });
        pass.value = '';
        if (!location.hash || location.hash === '#/login') history.replaceState(null, '', '#/');
        await ctx.onLogin();
      } catch (e) {
        msg.textContent = e.detail;
        pass.select();
      } finally {
        btn.disabled = false;
      }
    });
    el.append(h('div', { class: 'login-wrap' }, form));
    user.focus();
  },
};
