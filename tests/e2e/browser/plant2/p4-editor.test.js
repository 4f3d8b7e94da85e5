// The screen builder on another plant: an administrator draws a screen with
// a breaker, a value, a command button, a trend and a label that is markup,
// bound to that plant's tags by picking them, and saves it; an operator
// opens it, sees live values, presses the button and sees the confirmed
// value; a Guest without access neither sees nor fetches it.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, toolbar, credentials, adminApi, requireOk, until, BASE } from '../lib.js';
import { ensureGuest } from '../fixtures.js';

const ID = 'feeder-view';
const XSS = '<img src=x onerror=alert(1)>';

async function pick(page, search, tag) {
  await page.locator('#pick-search').fill(search);
  await page.locator(`.pick-tag[data-tag="${tag}"]`).click();
  await page.locator('#pick-search').waitFor({ state: 'detached' });
}

async function setField(page, id, value) {
  await page.locator(`#${id}`).fill(String(value));
  await page.locator(`#${id}`).press('Tab');
}

/** Places the selected (just added) element at x, y. */
async function moveTo(page, x, y) {
  await setField(page, 'prop-x', x);
  await setField(page, 'prop-y', y);
}

test('an administrator builds a screen; an operator uses it; a guest cannot', async () => {
  const api = await adminApi();
  await api.call('DELETE', `/api/screens/${ID}`);
  const admin = credentials().administrator;
  const b = await launch('p4-editor');
  const page = b.page;
  page.on('dialog', (d) => { b.problems.push(`a JavaScript dialog opened: ${d.message()}`); d.dismiss(); });
  try {
    await login(page, admin.user, admin.password);
    await page.goto(`${BASE}/#/editor`);
    await page.locator('#editor-new').click();
    await page.locator('#editor-new-id').fill(ID);
    await page.locator('#editor-new-name').fill('Feeder view');
    await page.locator('dialog button[type="submit"]').click();
    // The picker names the new screen while it is not saved (issue 33, finding 11), never "No screens yet".
    await until('the picker shows the new screen', async () => (await page.locator('#editor-screens option:checked').textContent()) === `Feeder view (${ID}), not saved yet`, 5_000);
    assert.equal(await page.locator('#editor-screens option', { hasText: 'No screens yet' }).count(), 0, 'no "No screens yet" with a screen open');

    // A breaker bound to the first panel's ELCB, picked by search.
    await page.locator('[data-palette="breaker"]').click();
    await page.locator('#prop-pick-tag').click();
    await pick(page, 'ELCB status', 'PA.ELCB.Closed');
    await page.locator('#prop-tag', { hasText: 'PA.ELCB.Closed' }).waitFor();
    await moveTo(page, 20, 20);
    // A value display of the frequency, four decimals.
    await page.locator('[data-palette="value"]').click();
    await page.locator('#prop-pick-tag').click();
    await pick(page, 'frequency', 'PA.PA.Hz');
    await setField(page, 'prop-digits', 4);
    await setField(page, 'prop-label', 'Frequency');
    await moveTo(page, 200, 20);
    // A command button writing the plain device's setpoint.
    await page.locator('[data-palette="button"]').click();
    await page.locator('#prop-pick-tag').click();
    await pick(page, 'setpoint', 'RTU1.Setpoint');
    await setField(page, 'prop-value', '12.5');
    await setField(page, 'prop-label', 'Set 12.5 kW');
    await moveTo(page, 420, 20);
    // A small trend of the frequency.
    await page.locator('[data-palette="trend"]').click();
    await page.locator('#prop-add-pen').click();
    await pick(page, 'frequency', 'PA.PA.Hz');
    await moveTo(page, 20, 100);
    // A label that is markup: it must stay text.
    await page.locator('[data-palette="text"]').click();
    await setField(page, 'prop-text', XSS);
    await moveTo(page, 400, 120);
    assert.equal(await page.locator('#editor-canvas [data-element-index]').count(), 5);

    // Drag the breaker by 43 px: it snaps to the 10 px grid; undo puts it back.
    const cover = page.locator('#editor-canvas [data-element-index="0"] .el-cover');
    const box = await cover.boundingBox();
    await page.mouse.move(box.x + 5, box.y + 5);
    await page.mouse.down();
    await page.mouse.move(box.x + 48, box.y + 5, { steps: 5 });
    await page.mouse.up();
    await until('the breaker moved', async () => (await page.locator('#prop-x').inputValue()) === '60');
    await page.locator('#editor-undo').click();
    await until('undo moved it back', async () => {
      await page.locator('#editor-canvas [data-element-index="0"] .el-cover').click();
      return (await page.locator('#prop-x').inputValue()) === '20';
    });
    await page.locator('#editor-redo').click();
    await page.locator('#editor-undo').click();
    await b.screenshot('drawn');

    await page.locator('#editor-save').click();
    await page.locator('#editor-status', { hasText: 'as version 1' }).waitFor();
    const saved = requireOk(await api.call('GET', `/api/screens/${ID}`), 'saved screen');
    assert.equal(saved.version, 1);
    assert.deepEqual(saved.elements.map((e) => e.type), ['breaker', 'value', 'button', 'trend', 'text']);
    assert.equal(saved.elements[0].x, 20);
    assert.equal(saved.elements[4].text, XSS);
    // The new screen is in the administrator's toolbar at once.
    await until('the toolbar lists the new screen', async () => (await toolbar(page)).includes(`custom:${ID}`));
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }

  // An operator, made through the API, opens it (operators see drawn screens by default).
  const op = { user: 'e2e-operator-p4', password: 'operator-password-e2e-4' };
  const made = await api.call('POST', '/api/users', { name: op.user, role: 'operator', password: op.password });
  if (made.status === 409) requireOk(await api.call('POST', `/api/users/${op.user}/password`, { password: op.password }), 'operator password');
  else requireOk(made, 'creating the operator');
  const o = await launch('p4-operator');
  try {
    await login(o.page, op.user, op.password);
    assert.ok((await toolbar(o.page)).includes(`custom:${ID}`));
    await o.page.goto(`${BASE}/#/custom:${ID}`);
    await o.page.locator('#custom-screen [data-element-type="breaker"] .bk-text', { hasText: 'CLOSED' }).waitFor();
    const value = o.page.locator('#custom-screen [data-element-type="value"] .value');
    await value.filter({ hasText: 'Hz' }).waitFor();
    const first = await value.getAttribute('title');
    await until('the value updates live', async () => (await value.getAttribute('title')) !== first, 8000);
    // The label is text: no image element was made from it.
    const text = o.page.locator('#custom-screen [data-element-type="text"]');
    assert.equal(await text.textContent(), XSS);
    assert.equal(await o.page.locator('#custom-screen img').count(), 0);
    // The button writes its value after a confirmation, and shows the read-back.
    await o.page.locator('#custom-screen [data-element-type="button"] button').click();
    await o.page.locator('dialog button[type="submit"]', { hasText: 'Write' }).click();
    await o.page.locator('#custom-screen .el-readback', { hasText: '12.5' }).waitFor();
    assert.equal(requireOk(await api.call('GET', '/api/tags/RTU1.Setpoint'), 'tag').value, 12.5);
    await o.page.locator('#custom-screen canvas.el-trend-canvas').waitFor();
    await o.screenshot('operator-view');
    assert.deepEqual(o.problems, []);
  } finally {
    await o.close();
  }

  // A Guest (whose group may not open it) neither sees it nor fetches it.
  const guest = await ensureGuest(api);
  const g = await launch('p4-guest');
  try {
    await login(g.page, guest.user, guest.password);
    assert.ok(!(await toolbar(g.page)).includes(`custom:${ID}`));
    const status = await g.page.evaluate((id) => fetch(`/api/screens/${id}`).then((r) => r.status), ID);
    assert.equal(status, 403);
    await g.page.goto(`${BASE}/#/custom:${ID}`);
    await g.page.locator('.toast-error', { hasText: 'may not open' }).waitFor();
    assert.deepEqual(g.problems.filter((p) => !/403/.test(p)), []);
  } finally {
    await g.close();
  }
});
