// Accessibility (issue 15 #16): axe-core on the login page and on every
// screen of the demo plant, in the light and the dark theme, with alarms
// standing (a fault isolated, so trips, alarm rows and priority chips are on
// view): zero serious or critical findings.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, runAxe, until, BASE } from '../lib.js';
import { restorePanel } from '../fixtures.js';
import { axeEveryScreen, describe, setTheme } from '../a11y.js';

const PANEL = 'css1';

test('axe: no serious or critical finding on any screen, light and dark', async () => {
  const api = await adminApi();
  await restorePanel(api, PANEL);
  const c = credentials().administrator;
  const b = await launch('09-axe');
  const page = b.page;
  try {
    await page.goto(`${BASE}/`);
    await page.locator('#login-user').waitFor();
    const atLogin = [...await runAxe(page)];
    await setTheme(page, true);
    atLogin.push(...await runAxe(page));
    await setTheme(page, false);
    assert.deepEqual(atLogin.filter((v) => v.impact === 'serious' || v.impact === 'critical'), [], 'the login page');

    await login(page, c.user, c.password);
    // Alarms standing: a permanent fault isolated on a zone.
    requireOk(await api.call('POST', '/api/sim/faults', { panel: PANEL, zone: 2, kind: 'permanent' }), 'injecting a fault');
    await until('the zone isolated', async () => ((await api.call('GET', `/api/panels/${PANEL}`)).body.faulty_zones || []).includes(2), 45_000, 500);
    await page.locator('#footer-alarms tr.unacked').first().waitFor({ timeout: 20_000 });

    const report = await axeEveryScreen(page, 'demo', (label) => b.screenshot(label));
    assert.ok(report.screens.length >= 10, `every screen visited: ${report.screens.join(', ')}`);
    assert.deepEqual(describe(report.findings), [], 'no serious or critical finding');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await restorePanel(api, PANEL).catch(() => {});
  }
});
