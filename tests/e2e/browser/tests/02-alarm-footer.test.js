// 2. An alarm from a simulated fault appears in the footer; acknowledge it there.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until } from '../lib.js';
import { restorePanel } from '../fixtures.js';

const PANEL = 'css1';

test('a simulated fault raises an alarm in the footer, acknowledged there', async () => {
  const api = await adminApi();
  await restorePanel(api, PANEL);
  const c = credentials().operator;
  const b = await launch('02-alarm-footer');
  try {
    await login(b.page, c.user, c.password);
    await b.page.locator('#footer-alarms').waitFor();
    // Acknowledge what is there already, so the new alarm is the one we see.
    await b.page.locator('#ack-all').click();
    await until('no unacknowledged alarm left', async () => (await b.page.locator('#footer-alarms tr.unacked').count()) === 0);
    await b.screenshot('before-fault');

    requireOk(await api.call('POST', '/api/sim/faults', { panel: PANEL, zone: 1, kind: 'transient' }), 'injecting a transient fault');
    // The ELCB trip alarm of the panel arrives over the live socket.
    const row = b.page.locator('#footer-alarms tr.unacked', { hasText: /ELCB/ });
    await row.first().waitFor({ timeout: 20_000 });
    const selection = (await row.first().locator('td').nth(4).textContent()).trim();
    assert.match(selection, /css1/i, 'the alarm belongs to the panel\'s selection');
    // The ELCB's value in its own words, and the time it tripped under Since.
    const first = row.first();
    assert.match((await first.locator('td.alarm-value').textContent()).trim(), /^(TRIPPED|CLOSED)$/, 'the value in words, not FALSE/TRUE');
    assert.match((await first.locator('td.alarm-since').textContent()).trim(), /^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d$/);
    await b.page.locator('#footer-selection').selectOption(selection);
    await b.screenshot('alarm-in-footer');
    const countText = await b.page.locator('#footer-count').textContent();
    assert.match(countText, /\d+ shown/);

    // Ack Top acknowledges one; Ack All (with the selection filter) the rest.
    const before = await b.page.locator('#footer-alarms tr.unacked').count();
    assert.ok(before >= 1);
    await b.page.locator('#ack-top').click();
    await until('Ack Top acknowledged one alarm', async () => (await b.page.locator('#footer-alarms tr.unacked').count()) < before);
    await b.page.locator('#ack-all').click();
    await until('every alarm of the selection acknowledged', async () => (await b.page.locator('#footer-alarms tr.unacked').count()) === 0);
    await b.screenshot('acknowledged');
    // The server agrees, and the acknowledgement is an event naming the user.
    const alarms = requireOk(await api.call('GET', `/api/alarms?selection=${encodeURIComponent(selection)}`), 'reading alarms');
    assert.ok(alarms.alarms.every((a) => a.acked), 'all alarms of the selection are acknowledged on the server');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await restorePanel(api, PANEL).catch(() => {});
  }
});
