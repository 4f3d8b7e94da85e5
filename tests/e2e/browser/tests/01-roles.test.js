// 1. Log in as each role and see the right screens.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, toolbar, credentials, adminApi, BASE } from '../lib.js';
import { ensureGuest } from '../fixtures.js';

const EXPECTED = {
  administrator: ['main', 'ss1', 'css1', 'microgrid', 'units', 'network', 'alarms', 'events', 'trends', 'tags', 'devices', 'editor', 'simulation', 'users', 'reports', 'alarmkpi'],
  supervisor: ['main', 'ss1', 'css1', 'microgrid', 'units', 'network', 'alarms', 'events', 'trends', 'tags', 'devices', 'reports', 'alarmkpi'],
  operator: ['main', 'ss1', 'css1', 'microgrid', 'units', 'network', 'alarms', 'events', 'trends', 'tags', 'devices'],
  guest: ['main', 'microgrid', 'network', 'alarms', 'trends'],
};

test('each role sees exactly its screens; anonymous sees only the login', async () => {
  const creds = { ...credentials(), guest: await ensureGuest(await adminApi()) };
  const b = await launch('01-roles');
  // Chromium logs every API answer 404 as a console error ("Failed to load
  // resource"), which launch() lets pass: on this server alone no screen
  // may ask for what it does not have (the pair's state).
  const notFound = [];
  b.page.on('response', (r) => {
    if (r.status() === 404 && new URL(r.url()).pathname.includes('/api/')) notFound.push(r.url());
  });
  try {
    await b.page.goto(`${BASE}/`);
    await b.page.locator('#login-user').waitFor();
    assert.equal(await b.page.locator('#current-user').textContent(), 'Guest');
    assert.deepEqual(await toolbar(b.page), [], 'anonymous: no screens in the toolbar');
    assert.equal(await b.page.locator('#alarm-footer').isHidden(), true);
    await b.screenshot('anonymous-login');

    for (const role of ['administrator', 'supervisor', 'operator', 'guest']) {
      const c = creds[role];
      await login(b.page, c.user, c.password);
      const screens = await toolbar(b.page);
      // The toolbar shows what the server says this user may open...
      const session = await b.page.evaluate(() => fetch('/api/session').then((r) => r.json()));
      assert.deepEqual(screens, session.screens.filter((s) => EXPECTED.administrator.includes(s)), `${role}: toolbar = session screens`);
      // ...which for the demo's groups are the role's defaults.
      assert.deepEqual(screens, EXPECTED[role], `${role}: screens`);
      assert.equal(await b.page.locator('#current-user').textContent(), c.user);
      await b.page.locator('.panel-card').first().waitFor();
      await b.screenshot(`${role}-main`);
      await b.page.locator('#logout').click();
      await b.page.locator('#login-user').waitFor();
      assert.equal(await b.page.locator('#current-user').textContent(), 'Guest');
    }
    const wrong = await b.page.evaluate(() => fetch('/api/session', { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify({ username: 'admin', password: 'wrong-password' }) }).then((r) => r.status));
    assert.equal(wrong, 401);
    await b.page.locator('#login-user').fill('nobody');
    await b.page.locator('#login-password').fill('wrong');
    await b.page.locator('#login-submit').click();
    await b.page.locator('#login-error', { hasText: 'invalid username or password' }).waitFor();
    await b.screenshot('login-refused');
    assert.deepEqual(b.problems, []);
    assert.deepEqual(notFound, [], 'API answers 404 on a server alone');
  } finally {
    await b.close();
  }
});
