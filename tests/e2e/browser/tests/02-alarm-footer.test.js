// 2. An alarm from a simulated fault appears in the footer; acknowledge it
// there. The alarm history says why each row happened: an activation or a
// return while suppressed is named, never shown as "Suppressed → Suppressed".
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until, BASE } from '../lib.js';
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
    // The value column is the value now; the message keeps the value at activation.
    assert.deepEqual(await b.page.locator('#footer-alarms thead th').allTextContents().then((t) => t.slice(-2)), ['Message', 'Value now']);
    assert.match((await first.locator('td.alarm-value .alarm-value-now').textContent()).trim(), /^(TRIPPED|CLOSED)$/, 'the value in words, not FALSE/TRUE');
    // Once the value moved on, the value at activation (the message's) is labelled beside it.
    const at = first.locator('td.alarm-value .alarm-value-activation');
    if (await at.count()) assert.match((await at.textContent()).trim(), /^at activation: (TRIPPED|CLOSED)$/);
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

test('the alarm history names each cause: activated or returned while suppressed, never "Suppressed → Suppressed"', async () => {
  const api = await adminApi();
  await restorePanel(api, PANEL);
  const since = Date.now() - 1000;
  const c = credentials().operator;
  const b = await launch('02-alarm-history');
  try {
    // A trip suppresses the panel's undervoltage alarms; they activate and
    // return behind it, and the states alone (suppressed → suppressed) do not say which.
    requireOk(await api.call('POST', '/api/sim/faults', { panel: PANEL, zone: 1, kind: 'transient' }), 'injecting a transient fault');
    const hidden = await until('an activation while suppressed in the history', async () => {
      const r = requireOk(await api.call('GET', `/api/alarms/history?from=${since}&limit=2000`), 'alarm history');
      const rows = r.transitions.filter((t) => t.from_state === t.to_state && t.to_state === 'suppressed');
      return rows.some((t) => t.cause === 'activate') ? rows : false;
    }, 30_000, 500);
    // Let the reclose bring the voltage back, still inside the suppression hold.
    await restorePanel(api, PANEL);
    const r = requireOk(await api.call('GET', `/api/alarms/history?from=${since}&limit=2000`), 'alarm history');
    const same = r.transitions.filter((t) => t.from_state === t.to_state);
    assert.ok(same.length >= hidden.length);
    assert.ok(same.every((t) => typeof t.cause === 'string' && t.cause), 'every row without a state change carries its cause');
    const selection = hidden[0].selection;

    await login(b.page, c.user, c.password);
    await b.page.goto(`${BASE}/#/alarms`);
    await b.page.locator('#alarms-tab-history').click();
    await b.page.locator('#hist-selection').fill(selection);
    await b.page.locator('#hist-search').click();
    const rows = b.page.locator('#alarms-history tbody tr');
    await until('the history rows of the selection', async () => (await rows.count()) > 0 && (await b.page.locator('#alarms-history tbody tr[data-cause="activate"]').count()) > 0);
    const table = await b.page.locator('#alarms-history').evaluate((t) => ({
      head: [...t.querySelectorAll('thead th')].map((th) => th.textContent),
      rows: [...t.querySelectorAll('tbody tr')].map((tr) => ({
        cause: tr.dataset.cause,
        cells: [...tr.querySelectorAll('td')].map((td) => td.textContent.trim()),
        event: tr.querySelector('td.hist-cause').textContent.trim(),
        state: tr.querySelector('td.hist-state').textContent.trim(),
      })),
    }));
    assert.deepEqual(table.head.slice(3, 5), ['Event', 'State']);
    for (const row of table.rows) {
      for (const cell of row.cells) {
        const m = cell.match(/^(.+) → (.+)$/);
        assert.ok(!m || m[1] !== m[2], `no row reads "${cell}"`);
      }
      assert.doesNotMatch(row.cells.join(' | '), /Suppressed → Suppressed/);
      assert.ok(row.event, `every row says what happened: ${row.cells.join(' | ')}`);
    }
    const events = table.rows.map((row) => row.event);
    assert.ok(events.includes('Activated while suppressed'), `the activation behind the trip is named: ${events}`);
    const states = table.rows.filter((row) => row.event === 'Activated while suppressed').map((row) => row.state);
    assert.ok(states.every((st) => st === 'Suppressed'), `the state it stayed in, once: ${states}`);
    if (same.some((t) => t.cause === 'return' && t.selection === selection)) {
      assert.ok(events.includes('Returned to normal while suppressed'), `the return behind the trip is named: ${events}`);
    }
    await b.page.locator('#alarms-history tbody tr[data-cause="activate"]').first().scrollIntoViewIfNeeded();
    await b.screenshot('alarm-history');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await restorePanel(api, PANEL).catch(() => {});
  }
});
