// A frozen server (SIGSTOP) keeps its socket open and says nothing: within
// 3 s the HMI must say so, grey every value and turn the comm light to
// "server not answering"; when the server resumes, live values return.
// Runs last: it stops the server for a few seconds.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, BASE } from '../lib.js';

test('a frozen server is shown within 3 s, and its return', async (t) => {
  const pid = Number(process.env.GRIDSCADA_PID);
  if (!pid) { t.skip('GRIDSCADA_PID is not set (run through tests/e2e/browser.sh)'); return; }
  const c = credentials().operator;
  const b = await launch('p9-frozen');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/pa`);
    await page.locator('#comm-light', { hasText: 'Comm OK' }).waitFor();
    await page.locator('.panel-left .sl-value.q-good').first().waitFor();
    const stopped = Date.now();
    process.kill(pid, 'SIGSTOP');
    try {
      await page.locator('#comm-light', { hasText: 'Server not answering' }).waitFor({ timeout: 5000 });
      const shownAfter = Date.now() - stopped;
      assert.ok(await page.evaluate(() => document.body.classList.contains('disconnected')), 'values greyed');
      await page.locator('#banner', { hasText: 'not answering' }).waitFor();
      assert.equal(await page.locator('.panel-left .sl-value.q-good').count(), 0, 'no value still shown as Good');
      await b.screenshot('frozen');
      assert.ok(shownAfter <= 3000, `shown after ${shownAfter} ms`);
    } finally {
      process.kill(pid, 'SIGCONT');
    }
    await page.locator('#comm-light', { hasText: 'Comm OK' }).waitFor({ timeout: 20000 });
    await page.locator('.panel-left .sl-value.q-good').first().waitFor({ timeout: 10000 });
    assert.deepEqual(b.problems.filter((p) => !/WebSocket/.test(p)), []);
  } finally {
    await b.close();
  }
});
