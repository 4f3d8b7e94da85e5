// 6. Create, block and delete a user.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, Api, BASE } from '../lib.js';

test('an administrator creates, blocks, unblocks and deletes a user', async () => {
  const c = credentials().administrator;
  const name = `e2e-user-${Date.now().toString(36)}`;
  const password = 'e2e-password-123456';
  const b = await launch('06-users');
  const page = b.page;
  const row = page.locator(`#users-table tr[data-user="${name}"]`);
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/users`);
    await page.locator('#new-user-name').fill(name);
    await page.locator('#new-user-role').selectOption('operator');
    await page.locator('#new-user-password').fill(password);
    await page.locator('#new-user-submit').click();
    await row.waitFor();
    assert.match(await row.textContent(), /active/);
    await b.screenshot('created');
    const probe = new Api();
    assert.equal((await probe.login(name, password)).status, 200, 'the new user can log in');

    await row.locator('button[data-action="block"]').click();
    await row.locator('.badge', { hasText: 'BLOCKED' }).waitFor();
    await b.screenshot('blocked');
    assert.equal((await new Api().login(name, password)).status, 401, 'a blocked user cannot log in');
    // Blocking ends the sessions the user had.
    assert.equal((await probe.call('GET', '/api/session')).body.authenticated, false);

    await row.locator('button[data-action="unblock"]').click();
    await row.locator('.badge', { hasText: 'active' }).waitFor();

    // Delete asks for the name; a wrong one is not accepted by the form.
    await row.locator('button[data-action="delete"]').click();
    await page.locator('#delete-confirm').fill('not-the-name');
    await page.locator('dialog .btn-danger').click();
    assert.equal(await page.locator('dialog').isVisible(), true, 'wrong confirmation keeps the dialog open');
    await page.locator('#delete-confirm').fill(name);
    await b.screenshot('delete-confirm');
    await page.locator('dialog .btn-danger').click();
    await row.waitFor({ state: 'detached' });
    await b.screenshot('deleted');
    assert.equal((await new Api().login(name, password)).status, 401, 'a deleted user cannot log in');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
