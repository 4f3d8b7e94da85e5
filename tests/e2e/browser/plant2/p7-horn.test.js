// The horn (issue 15 #13): it sounds again and again while an alarm is
// unacknowledged, until silenced or acknowledged; a new alarm sounds again;
// mute is for a while and belongs to the session (a log out ends it).
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until, BASE } from '../lib.js';

test('the horn sounds until silenced or acknowledged; mute belongs to the session', async () => {
  const api = await adminApi();
  const { devices } = requireOk(await api.call('GET', '/api/devices'), 'devices');
  const device = devices.find((d) => !/\./.test(d.name))?.name || devices[devices.length - 1].name;
  const c = credentials().operator;
  const b = await launch('p7-horn');
  const page = b.page;
  const footer = page.locator('#alarm-footer');
  const beeps = async () => Number(await footer.getAttribute('data-horn-beeps'));
  // A test before this one may have left the device just back on line,
  // its comm alarm still active: acknowledged then, it would not sound again.
  const ALL = 'normal,unack_active,ack_active,unack_rtn,shelved,suppressed,out_of_service';
  const commActive = async () => requireOk(await api.call('GET', `/api/alarms?state=${ALL}`), 'alarms').alarms
    .some((a) => a.tag === `${device}.Comm.Connected` && a.active);
  try {
    await until('the device answers (its comm alarm clear)', async () => !(await commActive()), 30_000);
    await login(page, c.user, c.password);
    await page.locator('#ack-all').click();
    await until('no alarm waits', async () => (await footer.getAttribute('data-horn')) === 'quiet');

    requireOk(await api.call('POST', `/api/sim/devices/${device}/offline`, {}), 'offline');
    await until('the horn sounds', async () => (await footer.getAttribute('data-horn')) === 'sounding', 15_000);
    const first = await beeps();
    await until('it sounds again (not once per alarm)', async () => (await beeps()) >= first + 2, 8000);
    await b.screenshot('sounding');

    // Silence: quiet for these alarms, which still wait for acknowledgement.
    await page.locator('#footer-silence').click();
    assert.equal(await footer.getAttribute('data-horn'), 'silenced');
    const after = await beeps();
    await page.waitForTimeout(2500);
    assert.equal(await beeps(), after, 'no more beeps after Silence');

    // Mute: for a while, in this session only.
    await page.locator('#footer-mute').click();
    await page.locator('#footer-mute[aria-pressed="true"]', { hasText: 'Horn muted to' }).waitFor();
    await page.reload();
    await page.locator('#footer-mute[aria-pressed="true"]').waitFor();
    const stored = JSON.parse(await page.evaluate(() => sessionStorage.getItem('gridscada.alarmMuted')));
    assert.ok(stored.until > Date.now() && stored.until <= Date.now() + 16 * 60_000, 'the mute expires');
    assert.equal(await page.evaluate(() => localStorage.getItem('gridscada.alarmMuted')), null, 'not kept in the browser for good');
    await page.locator('#logout').click();
    // The log out ends (session deleted on the server) before the next
    // login: a page loaded while the DELETE is in flight still has a session.
    await page.locator('#login-user').waitFor();
    await login(page, c.user, c.password);
    await page.locator('#footer-mute[aria-pressed="false"]', { hasText: 'Mute horn' }).waitFor();

    // Acknowledged: the horn stops.
    await until('it sounds after the new login', async () => (await footer.getAttribute('data-horn')) === 'sounding', 8000);
    await page.locator('#ack-all').click();
    await until('acknowledged: quiet', async () => (await footer.getAttribute('data-horn')) === 'quiet', 8000);
    assert.deepEqual(b.problems, []);
  } finally {
    await api.call('POST', `/api/sim/devices/${device}/online`, {});
    await b.close();
  }
});
