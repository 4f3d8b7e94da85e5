// Out of service from the alarm screen (issue 20): a supervisor takes a
// plain device's comm alarm out of service with a reason and an end, sees
// who, why and until when on the row, and returns it to service.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until } from '../lib.js';

const ALL = 'normal,unack_active,ack_active,unack_rtn,shelved,suppressed,out_of_service';

test('a supervisor takes an alarm out of service and returns it', async () => {
  const api = await adminApi();
  const { panels } = requireOk(await api.call('GET', '/api/panels'), 'panels');
  const { devices } = requireOk(await api.call('GET', '/api/devices'), 'devices');
  const device = devices.find((d) => !panels.some((x) => d.name.startsWith(`${x.prefix}.`)))?.name;
  assert.ok(device, 'a plain device to take off line');
  const c = credentials().supervisor;
  const b = await launch('p6c-out-of-service');
  const page = b.page;
  const find = async () => requireOk(await api.call('GET', `/api/alarms?state=${ALL}`), 'alarms').alarms
    .find((a) => a.tag === `${device}.Comm.Connected`);
  try {
    requireOk(await api.call('POST', `/api/sim/devices/${device}/offline`, {}), 'offline');
    const alarm = await until('the comm alarm stands', async () => { const a = await find(); return a?.active ? a : null; }, 30_000);
    await login(page, c.user, c.password);
    await page.goto(`${page.url().split('#')[0]}#/alarms`);
    await page.locator(`#alarms-online [data-out-of-service="${alarm.id}"]`).click();
    await page.locator('#oos-hours').fill('4');
    await page.locator('#oos-reason').fill('instrument replaced');
    await page.locator('dialog button[type=submit]').click();
    const oos = await until('out of service on the server', async () => { const a = await find(); return a?.state === 'out_of_service' ? a : null; }, 10_000);
    assert.equal(oos.out_of_service.reason, 'instrument replaced');
    assert.equal(oos.out_of_service.by, c.user);
    const hours = (oos.out_of_service.until - oos.out_of_service.since) / 3_600_000;
    assert.ok(Math.abs(hours - 4) < 0.02, `ends 4 h later, not ${hours} h`);
    // Not annunciated, so not in the live list: in the shelved and out-of-service list.
    const row = page.locator(`#alarms-hidden tr[data-alarm-id="${alarm.id}"]`);
    await until('the row says who, why and until when', async () => /out of service until .* by .*: instrument replaced/.test(await row.innerText()), 10_000);
    await b.screenshot('out-of-service');

    assert.equal(await page.locator(`#alarms-online tr[data-alarm-id="${alarm.id}"]`).count(), 0, 'not in the live list');
    await page.locator(`#alarms-hidden [data-in-service="${alarm.id}"]`).click();
    await until('back in service on the server', async () => (await find())?.state !== 'out_of_service', 10_000);
    await until('gone from the out-of-service list', async () => (await row.count()) === 0, 10_000);
    assert.deepEqual(b.problems, []);
  } finally {
    await api.call('POST', `/api/sim/devices/${device}/online`, {});
    const a = await find().catch(() => null);
    if (a?.state === 'out_of_service') await api.call('DELETE', `/api/alarms/${a.id}/out-of-service`);
    // Leave the device answering and its comm alarm clear for the next test.
    await until('the device answers again', async () => !(await find())?.active, 30_000).catch(() => {});
    await b.close();
  }
});
