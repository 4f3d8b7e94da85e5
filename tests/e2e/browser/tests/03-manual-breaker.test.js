// 3. Operate a breaker in manual mode.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, BASE, until } from '../lib.js';
import { restorePanel } from '../fixtures.js';

const PANEL = 'ss1';

test('a supervisor switches to manual, opens and closes a zone breaker', async () => {
  const api = await adminApi();
  await restorePanel(api, PANEL);
  const c = credentials().supervisor;
  const b = await launch('03-manual-breaker');
  const page = b.page;
  const state = (name) => page.locator(`tr[data-breaker-row="${name}"] .bk-text`);
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/${PANEL}`);
    await state('zone3').filter({ hasText: 'CLOSED' }).waitFor();
    // In auto mode the commands are disabled, and the server would refuse them.
    assert.equal(await page.locator('button[data-breaker="zone3"][data-action="open"]').isDisabled(), true);
    const refused = await page.evaluate((p) => fetch(`/api/panels/${p}/breakers/zone3`, { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: '{"closed":false}' })
      .then(async (r) => ({ status: r.status, body: await r.json() })), PANEL);
    assert.equal(refused.status, 409, 'auto mode refuses a manual command');
    assert.ok(refused.body.detail, 'with a readable detail');

    await page.locator(`#${PANEL}-mode-manual`).click();
    await page.locator(`#${PANEL}-mode`, { hasText: 'MANUAL' }).waitFor();
    await b.screenshot('manual-mode');

    await page.locator('button[data-breaker="zone3"][data-action="open"]').click();
    await page.locator('dialog .btn-danger', { hasText: 'Open breaker' }).click();
    await state('zone3').filter({ hasText: 'OPEN' }).waitFor({ timeout: 10_000 });
    // The diagram agrees, in text as well as colour; the zone's load is dead.
    await page.locator('[data-breaker="zone3"].bk-open').first().waitFor();
    await b.screenshot('zone3-open');

    await page.locator('button[data-breaker="zone3"][data-action="close"]').click();
    await page.locator('dialog .btn-danger', { hasText: 'Close breaker' }).click();
    await state('zone3').filter({ hasText: 'CLOSED' }).waitFor({ timeout: 10_000 });
    await b.screenshot('zone3-closed');

    await page.locator(`#${PANEL}-mode-auto`).click();
    await page.locator(`#${PANEL}-mode`, { hasText: 'AUTO' }).waitFor();
    // Each command is an event naming the user.
    const ev = await until('the command events', async () => {
      const r = await api.call('GET', `/api/events?today=true&user=${c.user}&limit=50`);
      const list = (r.body && r.body.events) || [];
      return list.some((e) => /zone3/.test(e.message) && /open/.test(e.message)) && list.some((e) => /zone3/.test(e.message) && /close/.test(e.message)) ? list : false;
    });
    assert.ok(ev.length >= 2);
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await restorePanel(api, PANEL).catch(() => {});
  }
});
