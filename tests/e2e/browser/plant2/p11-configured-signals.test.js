// Only what a plant configures is drawn (issue 33, finding 3). Panel C of
// tests/plants/three-panels has no door contact, no voltage signal on its
// zone loads, and an analyzer with V L1, I L1 and P only: its diagrams (main
// and panel screens) and its analyzer table draw no "?" for those, while
// panel A, wired fully, still shows its door, its loads' states and every
// reading. "?" stays for a configured signal whose value is not known.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, BASE } from '../lib.js';

/** What a panel's diagram shows, once every breaker has its state. */
async function diagramText(page, root) {
  return page.locator(root).evaluate((svg) => ({
    unknown: [...svg.querySelectorAll('text')].filter((t) => t.textContent.includes('?')).map((t) => t.textContent),
    loads: [...svg.querySelectorAll('.sl-load .sl-state')].map((t) => t.textContent.trim()),
    io: [...svg.querySelectorAll('.sl-io .sl-label')].map((t) => t.textContent),
    analyzer: [...svg.querySelectorAll('.sl-pa .sl-value')].map((t) => t.firstChild ? t.firstChild.textContent : ''),
  }));
}

test('a panel draws only the signals its plant configures', async () => {
  const api = await adminApi();
  const { panels } = requireOk(await api.call('GET', '/api/panels'), 'panels');
  const sparse = panels.find((p) => p.id === 'pc');
  const full = panels.find((p) => p.id === 'pa');
  assert.ok(sparse && full, 'the test plant has panels pa and pc');
  const { tags } = requireOk(await api.call('GET', '/api/tags?search=PC.&limit=1000'), 'tags');
  const configured = new Set(tags.map((t) => t.name));
  assert.ok(!configured.has('PC.Door.Open') && !configured.has('PC.Zone1.Energised') && !configured.has('PC.PA.V_L2'),
    'panel C is wired sparsely');

  const c = credentials().operator;
  const b = await launch('p11-signals');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    for (const p of [sparse, full]) {
      await page.goto(`${BASE}/#/${p.id}`);
      const svg = '.panel-left svg.single-line';
      await page.waitForFunction((n) => [...document.querySelectorAll('.panel-left .sl-breaker[data-breaker^="zone"] .sl-state')]
        .filter((t) => /CLOSED|OPEN|TRIPPED/.test(t.textContent)).length === n, p.zones);
      // The analyzer's configured readings arrive every second.
      await page.waitForFunction(() => ![...document.querySelectorAll('.panel-left .sl-pa .sl-value')].some((t) => t.textContent.includes('?')), null, { timeout: 10_000 });
      const shown = await diagramText(page, svg);
      const rows = await page.locator(`section[aria-labelledby="pa-${p.id}"] tbody th, section[aria-labelledby="pa-${p.id}"] tbody td:first-child`)
        .evaluateAll((cells) => cells.map((c) => c.textContent));
      await b.screenshot(`panel-${p.id}`);
      if (p === sparse) {
        assert.deepEqual(shown.unknown, [], `panel C's diagram shows no "?": ${shown.unknown}`);
        assert.deepEqual(shown.loads.filter(Boolean), [], 'no state under a zone load without a voltage signal');
        assert.ok(!shown.io.includes('Door'), 'no door without a door contact');
        assert.deepEqual(shown.analyzer.map((t) => t.replace(/ -?\d.*$/, '')), ['V L1', 'I L1', 'P'],
          `the diagram's analyzer shows V L1, I L1 and P: ${shown.analyzer}`);
        assert.deepEqual(rows, ['Voltage L1', 'Current L1', 'Active power'], 'the analyzer table lists the configured readings only');
        assert.equal(await page.locator(`section[aria-labelledby="pa-${p.id}"] .q-bad`).count(), 0, 'no "?" rows in the analyzer table');
      } else {
        assert.ok(shown.io.includes('Door'), 'panel A shows its door');
        assert.equal(shown.loads.filter((t) => /ENERGISED|DEAD/.test(t)).length, p.zones, `panel A's loads are in words: ${shown.loads}`);
        assert.equal(shown.analyzer.length, 7, 'panel A shows every analyzer reading on its diagram');
        assert.ok(rows.length >= 10 && !rows.includes('Energy'), `panel A's table has its readings, and no Energy row (no kWh tag): ${rows}`);
      }
    }
    // The main screen's card of panel C: no "?" either.
    await page.goto(`${BASE}/#/main`);
    const card = `.panel-card[data-panel="${sparse.id}"] svg.single-line`;
    await page.locator(card).waitFor();
    await page.waitForFunction((sel) => ![...document.querySelectorAll(`${sel} text`)].some((t) => t.textContent.includes('?')), card, { timeout: 10_000 });
    assert.deepEqual((await diagramText(page, card)).unknown, []);
    await b.screenshot('main');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
