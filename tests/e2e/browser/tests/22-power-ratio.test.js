// The microgrid's "P / max" (issue 33, finding 3): "?" only for a power
// whose value is not known. A unit that has not run today (the diesel OFF,
// a Good 0 kW) shows no ratio ("—"), not "?".
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, until, BASE } from '../lib.js';

test('P / max: "?" only for an unknown power, "—" for a unit with no output today', async () => {
  const c = credentials().operator;
  const b = await launch('22-ratio');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/microgrid`);
    await page.locator('#mg-units-table tbody tr').first().waitFor();
    const rows = () => page.locator('#mg-units-table tbody tr').evaluateAll((trs) => trs.map((tr) => {
      const cell = (label) => [...tr.querySelectorAll('td')].find((td) => td.dataset.label === label);
      const p = cell('P').querySelector('.value');
      return { unit: tr.dataset.unit, pGood: p.classList.contains('q-good'), p: p.textContent, ratio: cell('P / max').querySelector('.value').textContent };
    }));
    await until('every unit has a Good power', async () => (await rows()).every((r) => r.pGood), 20_000);
    const shown = await rows();
    await b.screenshot('units');
    for (const r of shown) assert.notEqual(r.ratio, '?', `${r.unit}: P ${r.p} is Good, and P / max says "?"`);
    assert.ok(shown.some((r) => /%$/.test(r.ratio)), `a running unit shows its ratio: ${JSON.stringify(shown)}`);
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
