// p10. The session policy on a wall display (issue 15 #1): a screen on view
// stays logged in past its idle timeout; once nobody watches it (the page is
// hidden), a banner warns before it idles out and offers to stay logged in;
// left alone, it ends. The plant's [server.sessions] gives `display`
// accounts a 9 s idle timeout, warned 5 s before (tests/plants/three-panels).
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, adminApi, requireOk, until } from '../lib.js';

const wall = { user: 'e2e-wall-display', password: 'wall-display-password-10' };
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

test('a watched display stays logged in; an unwatched one is warned, can stay, then ends', async () => {
  const api = await adminApi();
  const made = await api.call('POST', '/api/users', { name: wall.user, role: 'display', password: wall.password });
  if (made.status === 409) requireOk(await api.call('POST', `/api/users/${wall.user}/password`, { password: wall.password }), 'display password');
  else requireOk(made, 'creating the display account');

  const b = await launch('p10-session');
  const page = b.page;
  const session = () => page.evaluate(async () => (await fetch('/api/session')).json());
  try {
    await login(page, wall.user, wall.password);
    const s = await session();
    assert.equal(s.role, 'display');
    assert.equal(s.idle_timeout_s, 9);
    assert.equal(s.warn_s, 5);
    // No command for a display: the breaker and Reset buttons are not offered.
    assert.equal(await page.locator('#toolbar a[data-screen="users"]').count(), 0);

    // Watched (visible) for longer than the idle timeout: still logged in,
    // and no warning. The waiting is the test: time must pass.
    await sleep(12_000);
    assert.equal(await page.locator('#session-warning').isVisible(), false, 'no warning while watched');
    assert.equal((await session()).authenticated, true, 'a watched screen stays logged in');

    // Nobody watches: the page is hidden, so neither the live connection nor
    // the HMI's polls count as activity any more.
    await page.evaluate(() => {
      Object.defineProperty(document, 'visibilityState', { configurable: true, get: () => 'hidden' });
      document.dispatchEvent(new Event('visibilitychange'));
    });
    const warning = page.locator('#session-warning');
    await warning.waitFor({ state: 'visible', timeout: 12_000 });
    assert.match(await warning.textContent(), /Your session ends in \d+ s for inactivity/);
    await b.screenshot('warning');
    // Stay logged in: the warning goes, and the session was kept.
    await page.locator('#session-keep').click();
    await warning.waitFor({ state: 'hidden' });
    // Left alone, it warns again and then ends on the server.
    await warning.waitFor({ state: 'visible', timeout: 12_000 });
    await until('the session ended on the server', async () => {
      const r = await page.evaluate(async () => (await fetch('/api/session', { headers: { 'X-Gridscada-Background': '1' } })).json());
      return r.authenticated === false;
    }, 15_000, 500);
    assert.match(await warning.textContent(), /ended|ends in [0-2] s/);
    // The next request of the HMI finds the session gone: the login page.
    await page.evaluate(() => { location.hash = '#/alarms'; });
    await page.locator('#login-user').waitFor({ timeout: 10_000 });
    await b.screenshot('ended');
    assert.deepEqual(b.problems.filter((p) => !/401/.test(p)), []);
  } finally {
    await b.close();
  }
});
