// Accessibility (issue 15 #16) on another plant: axe-core on every screen
// the toolbar offers (its panels, the drawn screens the editor tests saved,
// and the rest), in the light and the dark theme, with a fault isolated so
// alarms, trips and priority chips are on view: zero serious or critical.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until } from '../lib.js';
import { restorePanel } from '../fixtures.js';
import { axeEveryScreen, describe } from '../a11y.js';

test('axe on every screen of this plant: no serious or critical finding, light and dark', async () => {
  const api = await adminApi();
  const { panels } = requireOk(await api.call('GET', '/api/panels'), 'panels');
  const p = panels.find((x) => x.zones >= 2) || panels[0];
  await restorePanel(api, p.id, p.zones);
  const c = credentials().administrator;
  const b = await launch('pb-axe');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    requireOk(await api.call('POST', '/api/sim/faults', { panel: p.id, zone: p.zones, kind: 'permanent' }), 'injecting a fault');
    await until('the zone isolated', async () => ((await api.call('GET', `/api/panels/${p.id}`)).body.faulty_zones || []).includes(p.zones), 60_000, 500);
    await page.locator('#footer-alarms tr.alarm-row').first().waitFor({ timeout: 20_000 });
    const report = await axeEveryScreen(page, 'plant2', (label) => b.screenshot(label));
    assert.ok(report.screens.length >= 8, `every screen visited: ${report.screens.join(', ')}`);
    assert.deepEqual(describe(report.findings), [], 'no serious or critical finding');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await restorePanel(api, p.id, p.zones).catch(() => {});
  }
});
