// Engineering limits before the operator types (issue 33, finding 6): the
// tag details and the write dialog show a writable tag's limits, and the
// dialog refuses a value outside them in the server's own words, before
// anything is sent.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, BASE } from '../lib.js';

const TAG = 'MG.BESS1.Setpoint_kW'; // a storage unit: -max_charge_kw to max_discharge_kw

test('the write dialog shows the engineering limits and refuses a value outside them in the server\'s words', async () => {
  const api = await adminApi();
  const tag = requireOk(await api.call('GET', `/api/tags/${encodeURIComponent(TAG)}`), 'the tag');
  assert.ok(tag.limits && tag.limits.min !== null && tag.limits.max !== null, `the API gives the limits: ${JSON.stringify(tag.limits)}`);
  const range = `${tag.limits.min} to ${tag.limits.max}`;
  // What the server says to a value outside them.
  const outside = tag.limits.max + 1000;
  const refused = await api.call('POST', `/api/tags/${encodeURIComponent(TAG)}/write`, { value: outside });
  const serverWords = JSON.stringify(refused.body);
  assert.equal(refused.status, 400, serverWords);
  const words = `is outside the engineering limits of '${TAG}' (${range}); nothing was written`;
  assert.ok(serverWords.includes(words), `the server's words: ${serverWords}`);

  const c = credentials().supervisor;
  const b = await launch('18-write-limits');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/tags`);
    await page.locator('#tag-search').fill(TAG);
    await page.locator(`#tag-list .vlist-row[data-tag="${TAG}"]`).click();
    assert.equal(await page.locator('#tag-limits').textContent(), `${range} kW`, 'the details show the limits');
    await page.locator('#tag-write').click();
    assert.equal(await page.locator('#write-limits').textContent(), `Engineering limits: ${range} kW`, 'the dialog shows them before typing');
    const input = page.locator('#write-value');
    await input.fill(String(outside));
    const message = await input.evaluate((e) => e.validationMessage);
    const expected = `${outside} is outside the engineering limits of '${TAG}' (${range}); nothing was written`;
    assert.equal(message, expected, 'the dialog refuses it, in the server\'s words');
    // "Next" does not leave the dialog with a value outside the limits.
    await page.locator('dialog button[type="submit"]').click();
    assert.equal(await page.locator('dialog #write-value').count(), 1, 'the dialog stays open');
    await input.fill(String(tag.limits.max));
    assert.equal(await input.evaluate((e) => e.validationMessage), '', 'a value inside is taken');
    await page.locator('dialog button', { hasText: 'Cancel' }).click();
    await b.screenshot('write-limits');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
