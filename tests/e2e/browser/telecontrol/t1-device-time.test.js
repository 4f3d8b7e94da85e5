// Telecontrol points on a drawn screen (the test plant tests/plants/telecontrol:
// panel FX on an IEC 104 RTU, panel FY on a DNP3 outstation, both simulated
// by the demo). The administrator draws, in the editor, a breaker and a
// value of each with their time shown; an operator opens the screen and
// sees both positions in words and both values with their device time
// stamps to the millisecond, equal to the samples' timestamps in the API
// (the RTU's CP56Time2a, the outstation's event time). A zone opened from
// the simulator is seen with its new time.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until, BASE } from '../lib.js';

const ID = 'telecontrol-times';

async function pick(page, search, tag) {
  await page.locator('#pick-search').fill(search);
  await page.locator(`.pick-tag[data-tag="${tag}"]`).click();
  await page.locator('#pick-search').waitFor({ state: 'detached' });
}

async function setField(page, id, value) {
  await page.locator(`#${id}`).fill(String(value));
  await page.locator(`#${id}`).press('Tab');
}

/** Adds an element of `palette` bound to `tag`, its time shown, at x, y. */
async function add(page, palette, search, tag, label, x, y) {
  await page.locator(`[data-palette="${palette}"]`).click();
  await page.locator('#prop-pick-tag').click();
  await pick(page, search, tag);
  await setField(page, 'prop-label', label);
  await page.locator('#prop-time').check();
  await setField(page, 'prop-w', 260);
  await setField(page, 'prop-x', x);
  await setField(page, 'prop-y', y);
}

/** "HH:MM:SS.mmm" of a timestamp (ms), in the browser's local time as the HMI shows it. */
async function clock(page, ms) {
  return page.evaluate((t) => {
    const d = new Date(t);
    const p = (n, w = 2) => String(n).padStart(w, '0');
    return `${p(d.getHours())}:${p(d.getMinutes())}:${p(d.getSeconds())}.${p(d.getMilliseconds(), 3)}`;
  }, ms);
}

test('an IEC 104 and a DNP3 point on a drawn screen, with their device time stamps', async () => {
  const api = await adminApi();
  await api.call('DELETE', `/api/screens/${ID}`);
  // Both devices answer (over IEC 104 and DNP3) before anything is drawn.
  for (const tag of ['FX.Zone2.Closed', 'FY.Zone2.Closed', 'FX.PA.V_L1', 'FY.PA.V_L1']) {
    await until(`${tag} Good`, async () => {
      const t = (await api.call('GET', `/api/tags/${tag}`)).body;
      return t && t.quality && t.quality.code === 'good';
    });
  }
  const admin = credentials().administrator;
  const b = await launch('t1-editor');
  try {
    await login(b.page, admin.user, admin.password);
    await b.page.goto(`${BASE}/#/editor`);
    await b.page.locator('#editor-new').click();
    await b.page.locator('#editor-new-id').fill(ID);
    await b.page.locator('#editor-new-name').fill('Telecontrol times');
    await b.page.locator('dialog button[type="submit"]').click();
    await add(b.page, 'breaker', 'FX.Zone2.Closed', 'FX.Zone2.Closed', 'FX zone 2 (IEC 104)', 20, 20);
    await add(b.page, 'value', 'FX.PA.V_L1', 'FX.PA.V_L1', 'FX L1 (IEC 104)', 320, 20);
    await add(b.page, 'breaker', 'FY.Zone2.Closed', 'FY.Zone2.Closed', 'FY zone 2 (DNP3)', 20, 140);
    await add(b.page, 'value', 'FY.PA.V_L1', 'FY.PA.V_L1', 'FY L1 (DNP3)', 320, 140);
    await b.page.locator('#editor-save').click();
    await b.page.locator('#editor-status', { hasText: 'as version 1' }).waitFor();
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
  const saved = requireOk(await api.call('GET', `/api/screens/${ID}`), 'saved screen');
  assert.deepEqual(saved.elements.map((e) => [e.type, e.tag, e.time]), [
    ['breaker', 'FX.Zone2.Closed', true], ['value', 'FX.PA.V_L1', true],
    ['breaker', 'FY.Zone2.Closed', true], ['value', 'FY.PA.V_L1', true]]);

  // An operator opens it.
  const op = { user: 'e2e-operator-t1', password: 'operator-password-e2e-t1' };
  const made = await api.call('POST', '/api/users', { name: op.user, role: 'operator', password: op.password });
  if (made.status === 409) requireOk(await api.call('POST', `/api/users/${op.user}/password`, { password: op.password }), 'operator password');
  else requireOk(made, 'creating the operator');
  const o = await launch('t1-operator');
  try {
    await login(o.page, op.user, op.password);
    await o.page.goto(`${BASE}/#/custom:${ID}`);
    const el = (i) => o.page.locator(`#custom-screen [data-element-index="${i}"]`);
    for (const i of [0, 2]) await el(i).locator('.bk-text', { hasText: 'CLOSED' }).waitFor();
    for (const i of [1, 3]) await el(i).locator('.value', { hasText: 'V' }).waitFor();
    // Each shown time is its sample's timestamp, to the millisecond.
    for (const [i, tag] of [[0, 'FX.Zone2.Closed'], [2, 'FY.Zone2.Closed']]) {
      const t = requireOk(await api.call('GET', `/api/tags/${tag}`), tag);
      const want = await clock(o.page, t.timestamp);
      await until(`${tag}'s time on the screen`, async () => (await el(i).locator('.el-time').textContent()) === want, 8000);
    }
    for (const i of [1, 3]) {
      assert.match(await el(i).locator('.el-time').textContent(), /^\d\d:\d\d:\d\d\.\d\d\d$/);
    }
    await o.screenshot('closed');

    // Zone 2 of each panel opened (written through the API, as an operator
    // would): the position and its new time follow on the screen.
    for (const tag of ['FX.Zone2.Cmd', 'FY.Zone2.Cmd']) {
      requireOk(await api.call('POST', `/api/tags/${tag}/write`, { value: false }), `opening ${tag}`);
    }
    for (const [i, tag] of [[0, 'FX.Zone2.Closed'], [2, 'FY.Zone2.Closed']]) {
      await el(i).locator('.bk-text', { hasText: 'OPEN' }).waitFor();
      const t = requireOk(await api.call('GET', `/api/tags/${tag}`), tag);
      assert.equal(t.value, false);
      const want = await clock(o.page, t.timestamp);
      await until(`${tag}'s new time on the screen`, async () => (await el(i).locator('.el-time').textContent()) === want, 8000);
    }
    await o.screenshot('opened');
    assert.deepEqual(o.problems, []);
  } finally {
    await o.close();
    for (const tag of ['FX.Zone2.Cmd', 'FY.Zone2.Cmd']) await api.call('POST', `/api/tags/${tag}/write`, { value: true });
  }
});
