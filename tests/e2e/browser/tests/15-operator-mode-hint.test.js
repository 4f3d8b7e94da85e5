// The breaker card tells each role what it can do (issue 33, finding 10):
// in Auto mode an operator, who has no Auto/Manual buttons, is told that a
// supervisor switches the panel to Manual; a supervisor is told to use the
// buttons above.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, BASE } from '../lib.js';
import { restorePanel } from '../fixtures.js';

const PANEL = 'ss1';

async function hintFor(role) {
  const c = credentials()[role];
  const b = await launch(`15-mode-hint-${role}`);
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/${PANEL}`);
    const hint = page.locator(`#${PANEL}-bk-hint`);
    await hint.filter({ hasText: 'Auto mode' }).waitFor({ timeout: 15_000 });
    const out = {
      hint: await hint.textContent(),
      modeButtons: await page.locator(`#${PANEL}-mode-manual`).count(),
    };
    await b.screenshot('breakers');
    assert.deepEqual(b.problems, []);
    return out;
  } finally {
    await b.close();
  }
}

test('in Auto mode the breaker card says who can switch to Manual', async () => {
  const api = await adminApi();
  await restorePanel(api, PANEL);
  const operator = await hintFor('operator');
  assert.equal(operator.modeButtons, 0, 'an operator has no mode buttons');
  assert.match(operator.hint, /A supervisor can switch the panel to Manual/, `operator's hint: ${operator.hint}`);
  assert.doesNotMatch(operator.hint, /Switch to Manual/, 'the operator is not told to press a button it does not have');
  const supervisor = await hintFor('supervisor');
  assert.equal(supervisor.modeButtons, 1, 'a supervisor has the mode buttons');
  assert.match(supervisor.hint, /Switch to Manual \(above\)/, `supervisor's hint: ${supervisor.hint}`);
});
