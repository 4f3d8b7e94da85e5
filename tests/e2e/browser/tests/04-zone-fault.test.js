// 4. Watch a simulated zone fault isolate itself.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, BASE } from '../lib.js';
import { restorePanel } from '../fixtures.js';

const PANEL = 'ss1';
const ZONE = 2;

test('a permanent zone fault is isolated: that zone open, the others restored', async () => {
  const api = await adminApi();
  await restorePanel(api, PANEL);
  const c = credentials().operator;
  const b = await launch('04-zone-fault');
  const page = b.page;
  const state = (name) => page.locator(`tr[data-breaker-row="${name}"] .bk-text`);
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/${PANEL}`);
    await state(`zone${ZONE}`).filter({ hasText: 'CLOSED' }).waitFor();
    await b.screenshot('healthy');

    requireOk(await api.call('POST', '/api/sim/faults', { panel: PANEL, zone: ZONE, kind: 'permanent' }), 'injecting a permanent fault');
    // The ELCB trips first...
    await state('elcb').filter({ hasText: 'TRIPPED' }).waitFor({ timeout: 10_000 });
    await b.screenshot('elcb-tripped');
    // ...then the sequence finds the faulty zone and leaves it isolated.
    await page.locator(`#${PANEL}-faulty`, { hasText: `Zone ${ZONE}` }).waitFor({ timeout: 60_000 });
    await page.locator(`#${PANEL}-step`, { hasText: 'isolated' }).waitFor({ timeout: 30_000 });
    await b.screenshot('isolated');
    assert.match(await state(`zone${ZONE}`).textContent(), /OPEN|TRIPPED/);
    for (const other of [1, 2, 3, 4].filter((z) => z !== ZONE)) {
      assert.equal(await state(`zone${other}`).textContent(), 'CLOSED', `zone ${other} restored`);
    }
    assert.equal(await state('elcb').textContent(), 'CLOSED');
    assert.equal(await page.locator(`#${PANEL}-lockout`).textContent(), 'no');
    const counters = [await page.locator(`#${PANEL}-count_c`).textContent(), await page.locator(`#${PANEL}-count_sv`).textContent()];
    assert.ok(counters.every((t) => /^\d+$/.test(t)), `counters shown: ${counters}`);
    // The main screen shows it too.
    await page.goto(`${BASE}/#/main`);
    await page.locator(`[data-panel="${PANEL}"] [data-breaker="zone${ZONE}"].bk-open, [data-panel="${PANEL}"] [data-breaker="zone${ZONE}"].bk-tripped`).waitFor();
    await b.screenshot('main-isolated');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await restorePanel(api, PANEL).catch(() => {});
  }
});
