// 7. Confirm that a Guest cannot command anything.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, adminApi, BASE } from '../lib.js';
import { ensureGuest } from '../fixtures.js';

const COMMANDS = [
  ['POST', '/api/panels/ss1/breakers/zone1', { closed: false }],
  ['POST', '/api/panels/ss1/mode', { mode: 'manual' }],
  ['POST', '/api/panels/ss1/reset', {}],
  ['POST', '/api/tags/SS1.Zone1.Cmd/write', { value: false }],
  ['POST', '/api/alarms/ack', { all: true }],
  ['POST', '/api/alarms/1/shelve', { minutes: 5, reason: 'test' }],
  ['POST', '/api/users', { name: 'x', role: 'administrator' }],
  ['POST', '/api/sim/faults', { panel: 'ss1', zone: 1, kind: 'permanent' }],
];

async function tryAll(page) {
  return page.evaluate(async (cmds) => {
    const out = [];
    for (const [method, path, body] of cmds) {
      const r = await fetch(path, { method, headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body) });
      out.push([path, r.status]);
    }
    return out;
  }, COMMANDS);
}

test('a Guest (and an anonymous visitor) cannot command anything', async () => {
  const guest = await ensureGuest(await adminApi());
  const b = await launch('07-guest');
  const page = b.page;
  try {
    // Anonymous: every command is refused as unauthenticated.
    await page.goto(`${BASE}/`);
    for (const [path, status] of await tryAll(page)) assert.equal(status, 401, `anonymous ${path}`);

    await login(page, guest.user, guest.password);
    await page.locator('.panel-card').first().waitFor();
    await page.locator('.sl-breaker').first().waitFor();
    // No command controls anywhere on the screens a guest may open.
    assert.equal(await page.locator('#ack-top, #ack-all').count(), 0, 'no Ack buttons in the footer');
    assert.equal(await page.locator('.sl-clickable').count(), 0, 'breakers in the diagram are not clickable');
    await b.screenshot('guest-main');
    await page.goto(`${BASE}/#/ss1`);
    await page.locator('.toast-error', { hasText: 'may not open' }).waitFor();
    assert.equal(await page.locator('button[data-breaker]').count(), 0);
    await page.goto(`${BASE}/#/alarms`);
    await page.locator('#alarms-online').waitFor();
    assert.equal(await page.locator('#alarms-online button').count(), 0, 'no Ack or Shelve on the alarm screen');
    await b.screenshot('guest-alarms');

    // And the server refuses every command, with a reason.
    for (const [path, status] of await tryAll(page)) assert.equal(status, 403, `guest ${path}`);
    const detail = await page.evaluate(() => fetch('/api/panels/ss1/reset', { method: 'POST' }).then((r) => r.json()));
    assert.match(detail.detail, /role/);
    assert.deepEqual(b.problems.filter((p) => !/40[13]/.test(p)), []);
  } finally {
    await b.close();
  }
});
