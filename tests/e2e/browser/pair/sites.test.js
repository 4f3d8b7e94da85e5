// Several sites on one database (docs/REDUNDANCY.md): from server b of the
// pair (site "main"), the operator reads the other site's ("south") events
// alarm history and trends through the screens' Site choice.
//
// Run by tests/e2e/pair_browser.sh after failover.test.js: GRIDSCADA_PAIR_OTHER
// is server b; the south site's server logged the operator in once.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, credentials, until } from '../lib.js';

const B = process.env.GRIDSCADA_PAIR_OTHER;

/** The messages of the events table now shown. */
const messages = (page) => page.locator('#events-table tbody tr td:nth-child(5)').allTextContents();

test("the history screens read another site's events, alarm history and trends", async () => {
  assert.ok(B, 'GRIDSCADA_PAIR_OTHER is not set');
  const op = credentials().operator;
  const b = await launch('pair-sites');
  const page = b.page;
  try {
    await page.goto(`${B}/`);
    await page.locator('#login-user').fill(op.user);
    await page.locator('#login-password').fill(op.password);
    await page.locator('#login-submit').click();
    await page.locator('#current-user', { hasText: op.user }).waitFor();

    await page.goto(`${B}/#/events`);
    const site = page.locator('#events-site');
    await site.waitFor({ state: 'visible' });
    assert.deepEqual(await site.locator('option').evaluateAll((o) => o.map((x) => x.value)), ['main', 'south']);
    assert.equal(await site.inputValue(), 'main');
    await page.locator('#events-table').waitFor();
    const own = await messages(page);
    assert.ok(own.some((m) => m.includes('failover ticket')), `own events: ${own}`);

    await site.selectOption('south');
    await page.locator('#events-search').click();
    let south = [];
    await until("the south's events", async () => {
      south = await messages(page);
      return south.some((m) => m.includes('logged in')) && !south.some((m) => m.includes('failover ticket'));
    }, 15_000);
    await b.screenshot('south-events');

    // The alarm history: the south's devices do not answer (no simulator).
    await page.goto(`${B}/#/alarms`);
    await page.locator('#alarms-tab-history').click();
    const histSite = page.locator('#hist-site');
    await histSite.waitFor({ state: 'visible' });
    await histSite.selectOption('south');
    await page.locator('#hist-search').click();
    await until("the south's alarm history", async () =>
      (await page.locator('#alarms-history tbody tr').count()) > 0, 30_000, 1000);
    await b.screenshot('south-alarm-history');

    // A trend of the same tag at the other site.
    await page.goto(`${B}/#/trends`);
    await page.locator('#trend-pen-input').fill('SS1.PA.V_L1');
    await page.locator('#trend-add-pen button[type="submit"]').click();
    const trendSite = page.locator('#trend-site');
    await trendSite.waitFor({ state: 'visible' });
    const [answer] = await Promise.all([
      page.waitForResponse((r) => r.url().includes('/api/trends?') && r.url().includes('site=south')),
      trendSite.selectOption('south'),
    ]);
    assert.equal(answer.status(), 200, await answer.text());
    const trend = await answer.json();
    assert.ok(trend.series.some((x) => x.tag === 'SS1.PA.V_L1'), JSON.stringify(trend.series.map((x) => x.tag)));
    assert.match(await page.locator('#trend-csv').getAttribute('href'), /site=south/);
    await b.screenshot('south-trend');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
