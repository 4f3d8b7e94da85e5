// Every screen of another plant (no microgrid) at 1366x768, 1920x1080 and 390 px, light and
// dark (issue 33): one-row header, no sideways page scroll, and a screenshot
// of each (ARTIFACTS/pc-layout-*.png) to look at.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials } from '../lib.js';
import { layoutEveryScreen } from '../layout.js';

test('every screen of another plant, at three sizes, light and dark', async () => {
  const c = credentials().administrator;
  const b = await launch('pc-layout');
  try {
    await login(b.page, c.user, c.password);
    const { screens, problems } = await layoutEveryScreen(b.page, (label) => b.screenshot(label));
    assert.ok(screens.length >= 8, `every screen visited: ${screens}`);
    assert.deepEqual(problems, []);
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
