// 8. The microgrid screen shows the dispatch's look-ahead plan.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, until, BASE } from '../lib.js';

test('microgrid: the look-ahead plan, its forecast and the value of stored energy', async () => {
  const c = credentials().operator;
  const b = await launch('08-microgrid-plan');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/microgrid`);
    const plan = page.locator('#dispatch-plan');
    await plan.waitFor({ timeout: 30_000 });
    // The demo plant plans 16 periods of 15 minutes (4 h).
    await page.locator('#mg-plan', { hasText: '4.0 h' }).waitFor();
    // The overview shows the battery's state of charge, and units on today's maxima.
    await page.locator('#mg-units-table [data-soc] .value', { hasText: '%' }).first().waitFor();
    await page.locator('#mg-units-table [data-max]', { hasText: 'kW' }).first().waitFor();
    const rows = page.locator('#dispatch-plan-table tbody tr');
    await rows.first().waitFor();
    assert.equal(await rows.count(), 16);
    // Period 0 is the demand measured now: a plausible microgrid load.
    const demand = await rows.nth(0).locator('td').nth(1).textContent();
    assert.match(demand, /^\d+(\.\d+)? kW$/, `forecast demand "${demand}"`);
    const kw = parseFloat(demand);
    assert.ok(kw > 20 && kw < 200, `demand ${kw} kW`);
    // The planned state of charge of the battery, in every period.
    const head = await page.locator('#dispatch-plan-table thead').textContent();
    assert.ok(head.includes('bess1 SoC'), head);
    const soc = await rows.nth(15).locator('td').nth(3).textContent();
    assert.match(soc, /^\d+(\.\d+)? kWh$/, `planned SoC "${soc}"`);
    // What a stored kWh is worth to the dispatch, as the API says (the plan
    // is renewed every minute: compare a reading of both taken together).
    await until('the screen showing the plan the API gives', async () => {
      const api = await page.evaluate(async () => (await (await fetch('/api/dispatch')).json()).horizon);
      const m = (await plan.textContent()).match(/Value of stored energy \(bess1\)([\d.]+) per kWh/);
      return api && api.status === 'optimal' && m
        && Math.abs(Number(m[1]) - api.stored_energy_value_per_kwh.bess1) < 0.0006;
    }, 20_000, 500);
    await b.screenshot('plan');
  } finally {
    await b.close();
  }
});
