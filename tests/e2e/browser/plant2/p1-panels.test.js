// A plant that is not the demo (tests/plants/three-panels): every panel
// screen draws with its own configured zone count, and nothing else is there.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, toolbar, credentials, adminApi, requireOk, BASE } from '../lib.js';

/**
 * The states that would be cut at their diagram's edge if they read "? UNKNOWN",
 * the widest (a lost module): each is set, measured and put back in one task,
 * so no live update comes in between.
 */
function cutIfUnknown(boxSelector) {
  return [...document.querySelectorAll(boxSelector)].flatMap((box) => {
    const r = box.getBoundingClientRect();
    return [...box.querySelectorAll('text.sl-state')].filter((t) => {
      const kids = [...t.childNodes];
      t.textContent = '? UNKNOWN';
      const b = t.getBoundingClientRect();
      t.replaceChildren(...kids);
      return b.right > r.right + 1 || b.left < r.left - 1;
    }).map((t) => t.closest('[data-breaker]')?.dataset.breaker || t.closest('[data-zone]')?.dataset.zone || t.textContent);
  });
}

test('every panel of another plant has its screen with its own zones', async () => {
  const api = await adminApi();
  const { panels } = requireOk(await api.call('GET', '/api/panels'), 'panels');
  assert.ok(panels.length >= 3, 'the test plant has three panels');
  const c = credentials().operator;
  const b = await launch('p1-panels');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    const bar = await toolbar(page);
    for (const p of panels) assert.ok(bar.includes(p.id), `toolbar has panel ${p.id}: ${bar}`);
    assert.ok(!bar.includes('microgrid'), 'no microgrid screen without a microgrid');
    assert.ok(bar.includes('tags') && bar.includes('devices'), 'tag browser and devices screens');
    for (const p of panels) {
      await page.goto(`${BASE}/#/${p.id}`);
      await page.locator(`svg.single-line[data-zones="${p.zones}"]`).waitFor();
      await page.locator('.sl-breaker[data-breaker="elcb"]').first().waitFor();
      const zones = await page.locator('.panel-left .sl-breaker[data-breaker^="zone"]').count();
      assert.equal(zones, p.zones, `${p.id}: zone breakers drawn`);
      assert.equal(await page.locator('tr[data-breaker-row^="zone"]').count(), p.zones, `${p.id}: zone rows`);
      assert.equal(await page.locator('h1.screen-title').textContent(), p.name);
      // Every zone's state is in words once the poller has read it.
      await page.waitForFunction((n) => [...document.querySelectorAll('.panel-left .sl-breaker[data-breaker^="zone"] .sl-state')]
        .filter((t) => /CLOSED|OPEN|TRIPPED/.test(t.textContent)).length === n, p.zones);
      await b.screenshot(`panel-${p.id}`);
      // No label or state is cut at the diagram card's edge (issue 33, finding 4: "Zone CLOS").
      const cut = await page.evaluate(() => {
        const box = document.querySelector('.panel-left .sl-scroll').getBoundingClientRect();
        return [...document.querySelectorAll('.panel-left svg.single-line text')]
          .filter((t) => t.textContent.trim() && (t.getBoundingClientRect().right > box.right + 1 || t.getBoundingClientRect().left < box.left - 1))
          .map((t) => t.textContent);
      });
      assert.deepEqual(cut, [], `${p.id}: labels cut at the card's edge at 1366 px`);
      assert.deepEqual(await page.evaluate(cutIfUnknown, '.panel-left .sl-scroll'), [], `${p.id}: "? UNKNOWN" would be cut at 1366 px`);
    }
    await page.goto(`${BASE}/#/main`);
    await page.locator('.panel-card').nth(panels.length - 1).waitFor();
    assert.equal(await page.locator('.panel-card').count(), panels.length);
    // Nor on the main screen's cards (a panel of many zones takes a whole row).
    const cutOnMain = await page.evaluate(() => [...document.querySelectorAll('.panel-card .sl-scroll')].flatMap((box) => {
      const r = box.getBoundingClientRect();
      return [...box.querySelectorAll('text')].filter((t) => t.textContent.trim()
        && (t.getBoundingClientRect().right > r.right + 1 || t.getBoundingClientRect().left < r.left - 1)).map((t) => t.textContent);
    }));
    assert.deepEqual(cutOnMain, [], 'labels cut on the main screen at 1366 px');
    assert.deepEqual(await page.evaluate(cutIfUnknown, '.panel-card .sl-scroll'), [], '"? UNKNOWN" would be cut on the main screen at 1366 px');
    await b.screenshot('main');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
