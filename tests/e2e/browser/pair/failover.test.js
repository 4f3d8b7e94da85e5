// A redundant pair (docs/REDUNDANCY.md): the HMI follows a failover without
// a new login. Logged in on the active server a, the operator's page stays
// open while a is killed (kill -9); the page moves to server b (its address
// from the pair's configuration, through /api/pair), shows b active, and is
// still logged in: b is another host (127.0.0.2), which a's session cookie
// is not sent to, so the HMI carries its failover ticket there.
//
// Run by tests/e2e/pair_browser.sh, which starts the pair: GRIDSCADA_URL is
// server a, GRIDSCADA_PAIR_OTHER server b, GRIDSCADA_PID server a's process.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, until, BASE } from '../lib.js';

const OTHER = process.env.GRIDSCADA_PAIR_OTHER;
const PID = Number(process.env.GRIDSCADA_PID);

test('the HMI follows a failover to the other server without a new login', async () => {
  assert.ok(OTHER, 'GRIDSCADA_PAIR_OTHER is not set');
  assert.ok(PID > 0, 'GRIDSCADA_PID is not set');
  const op = credentials().operator;
  const b = await launch('pair-failover');
  const page = b.page;
  const light = page.locator('#pair-light');
  try {
    await login(page, op.user, op.password);
    await light.filter({ hasText: 'Server a: active' }).waitFor({ timeout: 20_000 });
    await until('the pair to be healthy', async () => (await light.textContent()).includes('pair OK'), 20_000);
    await b.screenshot('a-active');

    const killed = Date.now();
    process.kill(PID, 'SIGKILL');
    const other = new URL(OTHER).origin;
    await until('the page to move to server b', async () => page.url().startsWith(other), 40_000, 250);
    const moved = Date.now() - killed;
    await light.filter({ hasText: 'Server b: active' }).waitFor({ timeout: 20_000 });
    const shown = Date.now() - killed;
    // Still logged in: the operator's name, no login form.
    await page.locator('#current-user', { hasText: op.user }).waitFor({ timeout: 10_000 });
    assert.equal(await page.locator('#login-user').count(), 0, 'the login form is shown');
    assert.ok(!page.url().includes('handover='), `the ticket is left in the address: ${page.url()}`);
    await page.locator('#toolbar a').first().waitFor();
    // The login came with the ticket (the cookie of a's host is not b's).
    const logins = await page.evaluate(async () => (await (await fetch('/api/events?type=login&limit=50')).json()).events);
    assert.ok(logins.some((e) => e.user === op.user && e.message.includes('failover ticket')),
      JSON.stringify(logins));
    await b.screenshot('b-active');
    console.log(`page on server b ${moved} ms after the kill; b shown active after ${shown} ms`);
    // The dead server's refused connections (live push, while the page
    // waits out the takeover) are expected; nothing else is.
    const dead = new URL(BASE).host;
    const refused = (m) => m.includes(dead) && m.includes('ERR_CONNECTION_REFUSED');
    assert.deepEqual(b.problems.filter((m) => !refused(m)), []);
  } finally {
    await b.close();
  }
});
