// ISA-101 look (issue 15): normal states grey, a deliberately opened breaker
// is not red (its colours read from the page), a trip is; alarm priority by
// colour AND shape; and the dark theme, toggled in the header and remembered
// by the browser.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until, BASE, rgb, isRed } from '../lib.js';
import { restorePanel } from '../fixtures.js';

const PANEL = 'ss1';
const ZONE = 3;

/** A grey (or black or white): no channel far from the others. */
const isGrey = (c) => { const v = rgb(c); return !v || Math.max(...v) - Math.min(...v) <= 24; };
const luminance = (c) => { const v = rgb(c).map((x) => x / 255).map((x) => (x <= 0.03928 ? x / 12.92 : ((x + 0.055) / 1.055) ** 2.4)); return 0.2126 * v[0] + 0.7152 * v[1] + 0.0722 * v[2]; };

/** The colours of a breaker as drawn: the symbol (fill, stroke), its state text, and the table's chip. */
async function breakerColours(page, name) {
  return page.evaluate((n) => {
    const g = document.querySelector(`.sl-breaker[data-breaker="${n}"]`);
    const rect = getComputedStyle(g.querySelector('rect'));
    const text = getComputedStyle(g.querySelector('.sl-state'));
    const chip = getComputedStyle(document.querySelector(`tr[data-breaker-row="${n}"] .bk-text`));
    return { fill: rect.fill, stroke: rect.stroke, text: text.fill, chipColor: chip.color, chipBg: chip.backgroundColor, chipText: document.querySelector(`tr[data-breaker-row="${n}"] .bk-text`).textContent };
  }, name);
}

test('ISA-101: an opened breaker is grey, not red, a trip is red; priority by colour and shape; dark theme remembered', async () => {
  const api = await adminApi();
  await restorePanel(api, PANEL);
  const c = credentials().supervisor;
  const b = await launch('10-isa101');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/${PANEL}`);
    const chip = (n) => page.locator(`tr[data-breaker-row="${n}"] .bk-text`);
    await chip(`zone${ZONE}`).filter({ hasText: 'CLOSED' }).waitFor();

    // Normal states are grey: a closed breaker, the mode, the comm light.
    const closed = await breakerColours(page, `zone${ZONE}`);
    for (const k of ['fill', 'stroke', 'text', 'chipColor', 'chipBg']) assert.ok(isGrey(closed[k]), `closed breaker ${k} is grey: ${closed[k]}`);
    const commOk = await page.locator('#comm-light.comm-ok').evaluate((e) => [getComputedStyle(e).color, getComputedStyle(e).backgroundColor]);
    assert.ok(commOk.every(isGrey), `"Comm OK" is grey: ${commOk}`);

    // A breaker opened on purpose (manual mode): hollow grey, never red.
    requireOk(await api.call('POST', `/api/panels/${PANEL}/mode`, { mode: 'manual' }), 'manual mode');
    requireOk(await api.call('POST', `/api/panels/${PANEL}/breakers/zone${ZONE}`, { closed: false }), 'opening the zone');
    await page.locator(`.sl-breaker[data-breaker="zone${ZONE}"].bk-open`).waitFor({ timeout: 10_000 });
    await chip(`zone${ZONE}`).filter({ hasText: 'OPEN' }).waitFor();
    const opened = await breakerColours(page, `zone${ZONE}`);
    for (const k of ['fill', 'stroke', 'text', 'chipColor', 'chipBg']) {
      assert.ok(!isRed(opened[k]), `opened breaker ${k} is not red: ${opened[k]}`);
      assert.ok(isGrey(opened[k]), `opened breaker ${k} is grey: ${opened[k]}`);
    }
    assert.notEqual(opened.fill, closed.fill, 'open (hollow) and closed (filled) differ in shape of fill');
    // Its dead load is not red either.
    const load = await page.locator(`.sl-load[data-zone="${ZONE}"] path`).evaluate((e) => getComputedStyle(e).fill);
    assert.ok(!isRed(load), `the dead load is not red: ${load}`);
    await b.screenshot('opened-breaker-light');

    // The shapes of the priorities: four bands, four glyphs, four colours.
    const bands = await page.evaluate(async () => {
      const m = await import('/js/components/alarmtable.js');
      const box = document.createElement('div');
      document.body.append(box);
      const out = [900, 700, 500, 100].map((p) => {
        const el = m.priorityChip(p);
        box.append(el);
        return { p, glyph: el.querySelector('.prio-glyph').textContent, bg: getComputedStyle(el).backgroundColor, band: el.dataset.band };
      });
      box.remove();
      return out;
    });
    assert.equal(new Set(bands.map((x) => x.glyph)).size, 4, `a shape per priority: ${JSON.stringify(bands)}`);
    assert.equal(new Set(bands.map((x) => x.bg)).size, 4, 'a colour per priority');
    assert.ok(isRed(bands[0].bg), 'urgent is red');

    // The dark theme: the header's toggle, remembered after a reload.
    const bodyBg = () => page.evaluate(() => getComputedStyle(document.documentElement).backgroundColor);
    assert.ok(luminance(await bodyBg()) > 0.5, 'light by default');
    await page.locator('#theme-toggle').click();
    await page.waitForFunction(() => document.documentElement.dataset.theme === 'dark');
    assert.equal(await page.locator('#theme-toggle').getAttribute('aria-pressed'), 'true');
    assert.ok(luminance(await bodyBg()) < 0.05, `dark background: ${await bodyBg()}`);
    await page.reload();
    await page.locator(`.sl-breaker[data-breaker="zone${ZONE}"].bk-open`).waitFor();
    assert.equal(await page.evaluate(() => document.documentElement.dataset.theme), 'dark', 'the theme is remembered');
    assert.equal(await page.locator('#theme-toggle').getAttribute('aria-pressed'), 'true');
    const openedDark = await breakerColours(page, `zone${ZONE}`);
    for (const k of ['fill', 'stroke', 'text', 'chipColor']) assert.ok(!isRed(openedDark[k]) && isGrey(openedDark[k]), `dark: opened breaker ${k} is grey: ${openedDark[k]}`);
    await b.screenshot('opened-breaker-dark');

    // A trip is red (an alarm), in both themes.
    requireOk(await api.call('POST', `/api/panels/${PANEL}/mode`, { mode: 'auto' }), 'auto mode');
    requireOk(await api.call('POST', '/api/sim/faults', { panel: PANEL, zone: 1, kind: 'transient' }), 'a transient fault');
    await page.locator('.sl-breaker[data-breaker="elcb"].bk-tripped').waitFor({ timeout: 20_000 });
    const tripped = await page.locator('.sl-breaker[data-breaker="elcb"] rect').evaluate((e) => getComputedStyle(e).fill);
    assert.ok(isRed(tripped), `a tripped breaker is red: ${tripped}`);
    await b.screenshot('tripped-dark');

    await page.locator('#theme-toggle').click();
    await page.waitForFunction(() => document.documentElement.dataset.theme !== 'dark');
    await page.reload();
    await page.locator('#toolbar a').first().waitFor();
    assert.equal(await page.evaluate(() => document.documentElement.dataset.theme || 'light'), 'light', 'back to light, remembered');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await restorePanel(api, PANEL).catch(() => {});
  }
});
