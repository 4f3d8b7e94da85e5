// Every screen of the demo at 1366x768, 1920x1080 and 390 px, light and
// dark (issue 33): one-row header, no sideways page scroll, and a screenshot
// of each (ARTIFACTS/21-layout-*.png) to look at.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials } from '../lib.js';
import { layoutEveryScreen } from '../layout.js';

test('every screen of the demo, at three sizes, light and dark', async () => {
  const c = credentials().administrator;
  const b = await launch('21-layout');
  try {
    await login(b.page, c.user, c.password);
    const { screens, problems } = await layoutEveryScreen(b.page, (label) => b.screenshot(label));
    assert.ok(screens.length >= 12, `every screen visited: ${screens}`);
    assert.deepEqual(problems, []);
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
