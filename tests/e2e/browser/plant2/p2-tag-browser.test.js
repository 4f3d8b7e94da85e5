// The tag browser on another plant: find a tag by search, see its quality
// and where it comes from, and write a value that the device confirms.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until, BASE } from '../lib.js';

test('the tag browser finds, explains and writes a tag', async () => {
  const c = credentials().operator;
  const b = await launch('p2-tags');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/tags`);
    await page.locator('#tag-tree .tree-label').first().waitFor();
    // The tree follows the dotted names.
    await page.locator('#tag-tree .tree-label[data-node="RTU1"]').waitFor();
    await page.locator('#tag-search').fill('pump power setp');
    const row = page.locator('#tag-list [data-tag="RTU1.Setpoint"]');
    await row.waitFor();
    assert.equal(await page.locator('#tag-list .vlist-row').count(), 1, 'the search narrows to one tag');
    await row.click();
    await page.locator('#tag-detail h2', { hasText: 'RTU1.Setpoint' }).waitFor();
    await page.locator('#tag-quality', { hasText: 'Good' }).waitFor();
    const source = await page.locator('#tag-source').textContent();
    assert.match(source, /RTU1/);
    assert.match(source, /holding register/);
    assert.match(source, /f32/);
    await b.screenshot('detail');
    // Write, confirm, and see the device's read-back.
    await page.locator('#tag-write').click();
    await page.locator('#write-value').fill('42.5');
    await page.locator('dialog button[type="submit"]').click();
    await page.locator('dialog button[type="submit"]', { hasText: 'Write' }).click();
    await page.locator('#tag-readback', { hasText: 'Confirmed by the device: 42.5' }).waitFor();
    await page.locator('#tag-value', { hasText: '42.5' }).waitFor();
    await b.screenshot('written');
    const api = await adminApi();
    const t = requireOk(await api.call('GET', '/api/tags/RTU1.Setpoint'), 'tag');
    assert.equal(t.value, 42.5);
    // Outside its limits, the write is refused in words and nothing changes: the dialog says so
    // before anything is sent (the server would refuse it too, in the same words).
    await page.locator('#tag-write').click();
    await page.locator('#write-value').fill('500');
    await page.locator('dialog button[type="submit"]').click();
    assert.match(await page.locator('#write-value').evaluate((e) => e.validationMessage), /engineering limits/);
    await page.locator('dialog button', { hasText: 'Cancel' }).click();
    const refused = await api.call('POST', '/api/tags/RTU1.Setpoint/write', { value: 500 });
    assert.equal(refused.status, 400);
    assert.match(JSON.stringify(refused.body), /engineering limits/);
    assert.equal(requireOk(await api.call('GET', '/api/tags/RTU1.Setpoint'), 'tag').value, 42.5);
    // "Add to trend" opens the trend with that pen.
    await page.locator('#tag-add-trend').click();
    await page.locator('#trend-pens li[data-pen="RTU1.Setpoint"]').waitFor();
    await until('the hash names the pen', async () => (await page.evaluate(() => location.hash)).includes('pens=RTU1.Setpoint'));
    assert.deepEqual(b.problems.filter((p) => !/400/.test(p)), []);
  } finally {
    await b.close();
  }
});
