// Small defects (issue 15 #17): the HMI has a favicon (no 404 on a page
// load), and an integer counter reads as an integer, not "1635.0".
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, until, BASE } from '../lib.js';

test('favicon served; integer counters shown without decimals', async () => {
  const c = credentials().operator;
  const b = await launch('p8-small');
  const page = b.page;
  const missing = [];
  page.on('response', (r) => { if (r.status() === 404) missing.push(r.url()); });
  try {
    for (const f of ['/favicon.ico', '/favicon.svg']) {
      const r = await fetch(`${BASE}${f}`);
      assert.equal(r.status, 200, `${f} is served`);
      assert.match(r.headers.get('content-type'), /^image\//);
    }
    await login(page, c.user, c.password);
    const icon = await page.evaluate(() => [...document.querySelectorAll('link[rel="icon"]')].map((l) => l.getAttribute('href')));
    assert.ok(icon.length >= 1, 'the page names its icon');
    await page.goto(`${BASE}/#/tags`);
    await page.locator('#tag-search').fill('comm.requests');
    const row = page.locator('#tag-list .vlist-row').first();
    await row.waitFor();
    await until('the counter has a value', async () => /\d/.test(await row.locator('.value').textContent()));
    // Every counter on view (some below 1000, which used to read "55.00").
    await until('every counter has a value', async () => (await page.locator('#tag-list .vlist-row .value').allTextContents()).every((t) => /\d/.test(t)));
    for (const text of await page.locator('#tag-list .vlist-row .value').allTextContents()) {
      assert.match(text.trim(), /^\d+$/, `a counter reads as an integer: "${text}"`);
    }
    await row.click();
    await until('the detail shows the counter', async () => /^\d+$/.test((await page.locator('#tag-value').textContent()).trim()));
    assert.deepEqual(missing.filter((u) => !/\/api\//.test(u)), [], 'no missing file on a page load');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
