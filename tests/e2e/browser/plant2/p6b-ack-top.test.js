// Ack Top (issue 15 #3) acknowledges exactly the row shown at the top of the
// footer, not the newest alarm: a device lost first (higher priority, shown
// on top), then a zone isolated (lower priority, newer).
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until } from '../lib.js';
import { restorePanel } from '../fixtures.js';

test('Ack Top acknowledges the row shown at the top', async () => {
  const api = await adminApi();
  const { panels } = requireOk(await api.call('GET', '/api/panels'), 'panels');
  const p = panels[0];
  const { devices } = requireOk(await api.call('GET', '/api/devices'), 'devices');
  const device = devices.find((d) => !d.name.startsWith(`${p.prefix}.`) && !panels.some((x) => d.name.startsWith(`${x.prefix}.`)))?.name;
  assert.ok(device, 'a plain device to take off line');
  await restorePanel(api, p.id, p.zones);
  const c = credentials().operator;
  const b = await launch('p6b-ack-top');
  const page = b.page;
  const rows = page.locator('#footer-alarms tr.alarm-row');
  try {
    await login(page, c.user, c.password);
    await page.locator('#ack-all').click();
    await until('nothing unacknowledged', async () => (await page.locator('#footer-alarms tr.unacked').count()) === 0);

    requireOk(await api.call('POST', `/api/sim/devices/${device}/offline`, {}), 'offline');
    await page.locator('#footer-alarms tr.unacked.active').first().waitFor({ timeout: 15_000 });
    requireOk(await api.call('POST', '/api/sim/faults', { panel: p.id, zone: 1, kind: 'permanent' }), 'fault');
    // Once the trip's alarms clear, the device's (older, higher) is on top and
    // the isolated zone's (newer, lower) below it.
    let newest = null;
    await until('the top row is not the newest alarm', async () => {
      const waiting = requireOk(await api.call('GET', '/api/alarms'), 'alarms').alarms.filter((a) => !a.acked && a.active);
      if (waiting.length < 2) return false;
      newest = waiting.reduce((x, y) => (y.last_change > x.last_change ? y : x));
      const top = Number(await rows.first().getAttribute('data-alarm-id'));
      return top !== newest.id && waiting.some((a) => a.id === top);
    }, 60_000, 500);
    await b.screenshot('before-ack-top');

    // Read the top row and press Ack Top in one step: alarms keep arriving
    // (a suppression ending annunciates what it held back), and a row that
    // arrives between a read and a click would take the top.
    const { topId, others } = await page.evaluate(() => {
      const shown = [...document.querySelectorAll('#footer-alarms tr.alarm-row.unacked')].map((r) => Number(r.dataset.alarmId));
      const top = Number(document.querySelector('#footer-alarms tr.alarm-row').dataset.alarmId);
      document.querySelector('#ack-top').click();
      return { topId: top, others: shown.filter((id) => id !== top) };
    });
    assert.ok(others.length >= 1, 'another unacknowledged alarm was shown below the top');
    const after = await until('the top row acknowledged on the server', async () => {
      const list = requireOk(await api.call('GET', '/api/alarms?state=normal,unack_active,ack_active,unack_rtn,shelved,suppressed,out_of_service'), 'alarms').alarms;
      return list.find((a) => a.id === topId)?.acked ? list : null;
    }, 10_000);
    // Exactly the top row: every other row shown unacknowledged stays so.
    for (const id of others) {
      assert.equal(after.find((a) => a.id === id)?.acked, false, `alarm ${id}, shown below the top, was not acknowledged`);
    }
    assert.deepEqual(b.problems, []);
  } finally {
    await api.call('POST', `/api/sim/devices/${device}/online`, {});
    await b.close();
    await restorePanel(api, p.id, p.zones).catch(() => {});
  }
});
