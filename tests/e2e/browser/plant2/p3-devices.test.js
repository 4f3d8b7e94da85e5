// The devices screen shows a device taken off line within two scans, and
// its return; the header's communication light leads there.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, BASE } from '../lib.js';

test('the devices screen shows a lost device within two scans', async () => {
  const api = await adminApi();
  const c = credentials().operator;
  const b = await launch('p3-devices');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.locator('#comm-light', { hasText: 'Comm OK' }).waitFor();
    await page.locator('#comm-light').click();
    await page.locator('#devices-table tr[data-device="RTU1"][data-connected="true"]').waitFor();
    const devices = requireOk(await api.call('GET', '/api/devices'), 'devices').devices;
    assert.equal(await page.locator('#devices-table tbody tr').count(), devices.length);
    await b.screenshot('all-ok');
    requireOk(await api.call('POST', '/api/sim/devices/RTU1/offline', {}), 'offline');
    const t0 = Date.now();
    // RTU1 scans every 500 ms with a 300 ms timeout: two scans plus the
    // timeout and one screen refresh.
    await page.locator('#devices-table tr[data-device="RTU1"][data-connected="false"]').waitFor({ timeout: 3000 });
    const shownAfter = Date.now() - t0;
    await page.locator('#comm-light', { hasText: 'RTU1' }).waitFor();
    await b.screenshot('rtu1-lost');
    requireOk(await api.call('POST', '/api/sim/devices/RTU1/online', {}), 'online');
    await page.locator('#devices-table tr[data-device="RTU1"][data-connected="true"]').waitFor({ timeout: 20000 });
    assert.ok(shownAfter < 3000, `shown after ${shownAfter} ms`);
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
