// Accessibility (issue 15 #16): focus lands on the screen's content after a
// log in (not the body); "Skip to content" goes to the content of the screen
// on view (not to Main); view buttons carry aria-pressed.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, credentials, BASE } from '../lib.js';

const focused = (page) => page.evaluate(() => ({ id: document.activeElement && document.activeElement.id, tag: document.activeElement && document.activeElement.tagName }));

test('focus after login, skip link on any screen, aria-pressed on view buttons', async () => {
  const c = credentials().operator;
  const b = await launch('11-a11y');
  const page = b.page;
  try {
    // Log in from a screen's address: focus goes to that screen's content.
    await page.goto(`${BASE}/#/alarms`);
    await page.locator('#login-user').fill(c.user);
    await page.locator('#login-password').fill(c.password);
    await page.locator('#login-password').press('Enter');
    await page.locator('#alarms-tab-online').waitFor();
    await page.waitForFunction(() => document.activeElement && document.activeElement.id === 'screen');
    assert.deepEqual(await focused(page), { id: 'screen', tag: 'MAIN' }, 'focus on the main content after login');

    // The view buttons are toggles with aria-pressed, one pressed at a time.
    const online = page.locator('#alarms-tab-online');
    const hist = page.locator('#alarms-tab-history');
    assert.equal(await online.getAttribute('aria-pressed'), 'true');
    assert.equal(await hist.getAttribute('aria-pressed'), 'false');
    await hist.click();
    await page.locator('#hist-from').waitFor();
    assert.equal(await online.getAttribute('aria-pressed'), 'false');
    assert.equal(await hist.getAttribute('aria-pressed'), 'true');
    assert.equal(await page.locator('[role="tab"]').count(), 0, 'no tab role that would forbid aria-pressed');

    // Skip to content from the alarm screen, with the keyboard: it stays here and focuses the content.
    for (const screen of ['alarms', 'trends', 'events']) {
      // A fresh load of the screen's address: the keyboard starts at the top of the page.
      await page.goto(`${BASE}/#/${screen}`);
      await page.reload();
      await page.locator(`#toolbar a[data-screen="${screen}"][aria-current="page"]`).waitFor({ state: 'attached' });
      await page.keyboard.press('Tab');
      const skip = page.locator('.skip-link');
      assert.equal(await skip.evaluate((e) => e === document.activeElement), true, 'the skip link is the first stop');
      const box = await skip.boundingBox();
      assert.ok(box && box.x >= 0, 'and visible when focused');
      if (screen === 'alarms') await b.screenshot('skip-link');
      await page.keyboard.press('Enter');
      await page.waitForFunction(() => document.activeElement && document.activeElement.id === 'screen');
      assert.equal(new URL(page.url()).hash, `#/${screen}`, `still on ${screen}, not Main`);
      assert.equal(await page.locator(`#toolbar a[data-screen="${screen}"]`).getAttribute('aria-current'), 'page');
    }

    // The units' buttons (the microgrid) also say which is pressed.
    await page.goto(`${BASE}/#/units`);
    const unitBtns = page.locator('#screen .tabs button');
    await unitBtns.first().waitFor();
    await page.waitForFunction(() => [...document.querySelectorAll('#screen .tabs button')].some((x) => x.getAttribute('aria-pressed') === 'true'));
    const pressed = await unitBtns.evaluateAll((bs) => bs.map((x) => x.getAttribute('aria-pressed')));
    assert.equal(pressed.filter((p) => p === 'true').length, 1, `one unit pressed: ${pressed}`);
    assert.ok(pressed.every((p) => p === 'true' || p === 'false'));
    await unitBtns.nth(1).click();
    await page.waitForFunction(() => document.querySelectorAll('#screen .tabs button')[1].getAttribute('aria-pressed') === 'true');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
