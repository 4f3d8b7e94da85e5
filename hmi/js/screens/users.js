// Users: new user, delete (with a typed confirmation), block and unblock,
// change role or password; and which screens each group may open.

import { get, post, patch, put, del, enc } from '../api.js';
import { h, replace, select, field } from '../dom.js';
import { ROLES, fmtTime } from '../format.js';
import { attempt, formDialog, toast } from '../ui.js';


export default {
  mount(el, ctx) {
    const listBox = h('section', { class: 'card', 'aria-labelledby': 'users-title' });
    const newBox = h('section', { class: 'card', 'aria-labelledby': 'new-user-title' });
    const groupBox = h('section', { class: 'card', 'aria-labelledby': 'groups-title' });
    el.append(h('h1', { class: 'screen-title', text: 'Users' }),
      h('div', { class: 'users-layout' }, listBox, h('div', { class: 'users-side' }, newBox, groupBox)));
    let users = [];

    async function loadUsers() {
      try {
        users = (await get('/api/users')).users || [];
      } catch (e) {
        replace(listBox, h('p', { class: 'error', text: `Cannot list users: ${e.detail}` }));
        return;
      }
      replace(listBox, h('h2', { id: 'users-title', text: 'Users' }),
        h('div', { class: 'table-wrap', tabindex: '0' }, h('table', { class: 'data', id: 'users-table' },
          h('thead', {}, h('tr', {}, ['Name', 'Role', 'Group', 'Status', 'Created', 'Password changed', 'Actions'].map((t) => h('th', { scope: 'col', text: t })))),
          h('tbody', {}, users.map(userRow)))));
      drawGroupPicker();
    }

    function userRow(u) {
      const self = u.name === ctx.session.user;
      const roleSel = select({ 'aria-label': `Role of ${u.name}`, disabled: self }, ROLES, u.role);
      roleSel.addEventListener('change', async () => {
        const r = await attempt(`Change the role of ${u.name}`, () => patch(`/api/users/${enc(u.name)}`, { role: roleSel.value }));
        if (r) toast(`${u.name} is now ${roleSel.value}.`, 'ok');
        loadUsers();
      });
      return h('tr', { class: u.blocked ? 'blocked' : '', dataset: { user: u.name } },
        h('th', { scope: 'row', text: u.name }),
        h('td', {}, roleSel),
        h('td', { text: u.group }),
        h('td', {}, h('span', { class: ['badge', u.blocked ? 'badge-bad' : 'badge-ok'], text: u.blocked ? 'BLOCKED' : 'active' })),
        h('td', { class: 'nowrap', text: fmtTime(u.created_at) }),
        h('td', { class: 'nowrap', text: fmtTime(u.password_changed_at) }),
        h('td', { class: 'actions' },
          h('button', { type: 'button', class: 'btn btn-small', dataset: { action: u.blocked ? 'unblock' : 'block' }, disabled: self,
            title: self ? 'You cannot block yourself' : '', onclick: () => setBlocked(u, !u.blocked), text: u.blocked ? 'Unblock' : 'Block' }),
          h('button', { type: 'button', class: 'btn btn-small', dataset: { action: 'password' }, onclick: () => setPassword(u), text: 'Password' }),
          h('button', { type: 'button', class: 'btn btn-small btn-danger', dataset: { action: 'delete' }, disabled: self,
            onclick: () => remove(u), text: 'Delete' })));
    }

    async function setBlocked(u, blocked) {
      const r = await attempt(`${blocked ? 'Block' : 'Unblock'} ${u.name}`, () => patch(`/api/users/${enc(u.name)}`, { blocked }));
      if (r) toast(`${u.name} is ${blocked ? 'blocked' : 'unblocked'}.`, 'ok');
      loadUsers();
    }

    async function setPassword(u) {
      const data = await formDialog(`New password for ${u.name}`, (f) => f.append(
        h('label', { class: 'field' }, h('span', { class: 'field-label', text: 'New password' }),
          h('input', { type: 'password', name: 'password', required: true, minlength: 8, autocomplete: 'new-password' }))),
      { submitLabel: 'Set password' });
      if (!data) return;
      const r = await attempt(`Set the password of ${u.name}`, () => post(`/api/users/${enc(u.name)}/password`, { password: String(data.get('password')) }));
      if (r !== undefined) toast(`Password of ${u.name} changed.`, 'ok');
      loadUsers();
    }

    async function remove(u) {
      const data = await formDialog(`Delete user ${u.name}`, (f) => f.append(
        h('p', { text: `This deletes ${u.name} and ends their sessions. Type the user name to confirm.` }),
        h('label', { class: 'field' }, h('span', { class: 'field-label', text: 'User name' }),
          h('input', { name: 'confirm', id: 'delete-confirm', required: true, autocomplete: 'off', pattern: u.name.replace(/[.*+?^${}()|[\]\\]/g, '\\$&') }))),
      { submitLabel: 'Delete user', danger: true });
      if (!data) return;
      const r = await attempt(`Delete ${u.name}`, () => del(`/api/users/${enc(u.name)}`, { confirm: String(data.get('confirm')) }));
      if (r !== undefined) toast(`${u.name} deleted.`, 'ok');
      loadUsers();
    }

    // New user: a password may be given, or the server generates one and shows it once.
    const nName = h('input', { id: 'new-user-name', name: 'name', required: true, autocomplete: 'off', pattern: '[A-Za-z0-9_.\\-]{1,64}' });
    const nRole = select({ id: 'new-user-role', name: 'role' }, ROLES, 'operator');
    const nGroup = h('input', { id: 'new-user-group', name: 'group', placeholder: 'default: the role' });
    const nPass = h('input', { id: 'new-user-password', name: 'password', type: 'password', autocomplete: 'new-password', placeholder: 'blank: generate one' });
    const newForm = h('form', { class: 'filters', id: 'new-user-form' },
      field('Name', nName), field('Role', nRole), field('Group', nGroup), field('Password', nPass),
      h('div', { class: 'btn-row' }, h('button', { type: 'submit', class: 'btn btn-primary', id: 'new-user-submit', text: 'Create user' })));
    replace(newBox, h('h2', { id: 'new-user-title', text: 'New user' }), newForm);
    newForm.addEventListener('submit', async (e) => {
      e.preventDefault();
      const body = { name: nName.value.trim(), role: nRole.value };
      if (nGroup.value.trim()) body.group = nGroup.value.trim();
      if (nPass.value) body.password = nPass.value;
      const r = await attempt(`Create ${body.name}`, () => post('/api/users', body));
      if (!r) return;
      nName.value = ''; nPass.value = ''; nGroup.value = '';
      if (r.password) {
        await formDialog(`User ${r.user.name} created`, (f) => f.append(
          h('p', { text: 'The generated password is shown only now. Give it to the user; they should change it.' }),
          h('p', {}, h('code', { id: 'generated-password', text: r.password }))), { submitLabel: 'Done', danger: false });
      } else {
        toast(`User ${r.user.name} created.`, 'ok');
      }
      loadUsers();
    });

    // Screen access per group.
    const groupSel = h('input', { id: 'group-name', list: 'group-names', size: 14 });
    const groupList = h('datalist', { id: 'group-names' });
    const screensBox = h('div', { class: 'screens-grid', id: 'group-screens', role: 'group', 'aria-label': 'Screens this group may open' });
    const groupForm = h('form', {},
      h('div', { class: 'filters' }, field('Group', groupSel), groupList,
        h('div', { class: 'btn-row' }, h('button', { type: 'button', class: 'btn', id: 'group-load', text: 'Load', onclick: () => loadGroup() }))),
      screensBox,
      h('div', { class: 'btn-row' }, h('button', { type: 'submit', class: 'btn btn-primary', id: 'group-save', text: 'Save screen access' })));
    replace(groupBox, h('h2', { id: 'groups-title', text: 'Screen access per group' }), groupForm);
    groupSel.addEventListener('change', () => loadGroup());
    groupForm.addEventListener('submit', async (e) => {
      e.preventDefault();
      const g = groupSel.value.trim();
      if (!g) { toast('Name a group first.', 'error'); return; }
      const screens = [...screensBox.querySelectorAll('input:checked')].map((i) => i.value);
      const r = await attempt(`Save screens of ${g}`, () => put(`/api/groups/${enc(g)}/screens`, { screens }));
      if (r) toast(`Group ${g} may open: ${r.screens.join(', ') || 'nothing'}.`, 'ok');
    });

    function drawGroupPicker() {
      const groups = [...new Set(users.map((u) => u.group))].sort();
      replace(groupList, groups.map((g) => h('option', { value: g })));
      if (!groupSel.value && groups.length) { groupSel.value = groups[0]; loadGroup(); }
    }

    async function loadGroup() {
      const g = groupSel.value.trim();
      if (!g) return;
      try {
        // Every screen of this plant, with its label (panels by name, drawn screens by title).
        const [r, catalog] = await Promise.all([get(`/api/groups/${enc(g)}/screens`), get('/api/screens')]);
        const on = new Set(r.screens);
        const label = new Map(catalog.screens.map((x) => [x.id, x.label]));
        replace(screensBox, (r.available || catalog.screens.map((x) => x.id)).map((s) => h('label', { class: 'check' },
          h('input', { type: 'checkbox', value: s, checked: on.has(s) }), label.get(s) || s)));
      } catch (e) {
        replace(screensBox, h('p', { class: 'error', text: `Cannot read group ${g}: ${e.detail}` }));
      }
    }

    loadUsers();
  },
};
