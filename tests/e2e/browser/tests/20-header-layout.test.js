// The header and the phone layout (issue 33, findings 1 and 2): the header is
// one row at 1366x768 and 1920x1080 for every role, with ten drawn screens;
// every screen is still reached from the grouped navigation, by mouse and by
// keyboard; on a 390-px phone the process comes first (a small header and
// alarm bar), the microgrid's unit table keeps P, setpoint and state on the
// screen, and the alarm screen shows its summary per area once.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until, runAxe, seriousFindings, BASE } from '../lib.js';

const DRAWN = Array.from({ length: 10 }, (_, i) => `e2e-nav-${i + 1}`);

/** Ten drawn screens with ordinary names, as a plant's engineers make them. */
async function drawTenScreens(api) {
  for (const [i, id] of DRAWN.entries()) {
    requireOk(await api.call('PUT', `/api/screens/${id}`, {
      id, name: `Feeder overview ${i + 1}`, width: 1200, height: 300,
      elements: [{ type: 'text', x: 10, y: 10, w: 200, h: 40, text: `Overview ${i + 1}` }],
    }), `saving drawn screen ${id}`);
  }
}

async function removeScreens(api) {
  for (const id of DRAWN) await api.call('DELETE', `/api/screens/${id}`);
}

/** The header's height and whether its items sit on one row. */
async function headerRows(page) {
  return page.evaluate(() => {
    const header = document.getElementById('header');
    const items = [...header.querySelectorAll('.brand, #toolbar > .tool-home, #toolbar > .tool-groups > .tool-group, .header-status > *')]
      .filter((e) => e.getBoundingClientRect().width > 0);
    const tops = items.map((e) => { const r = e.getBoundingClientRect(); return Math.round(r.top + r.height / 2); });
    return { height: Math.round(header.getBoundingClientRect().height), spread: Math.max(...tops) - Math.min(...tops), count: items.length };
  });
}

/** Opens a screen from the navigation as a user would: its group, then its link. */
async function openFromNavigation(page, id) {
  const link = page.locator(`#toolbar a[data-screen="${id}"]`);
  if (!(await link.isVisible())) {
    const group = await link.evaluate((a) => a.closest('.tool-group').dataset.group);
    await page.locator(`#toolbar button.tool-menu-button[data-group="${group}"]`).click();
  }
  await link.click();
  await page.locator(`#toolbar a[data-screen="${id}"][aria-current="page"]`).waitFor({ state: 'attached' });
  await until(`${id} is mounted`, async () => (await page.locator('#screen').getAttribute('class')).includes(`screen-${id.replace(':', '\\:')}`) || page.url().endsWith(`#/${id}`), 5_000);
  assert.ok(page.url().endsWith(`#/${id}`), `opened ${id}: ${page.url()}`);
}

test('the header is one row for every role at 1366x768 and 1920x1080, with ten drawn screens', async () => {
  const api = await adminApi();
  await drawTenScreens(api);
  // A panel in manual mode: the header's amber MANUAL light is on, naming it.
  const { panels } = requireOk(await api.call('GET', '/api/panels'), 'panels');
  requireOk(await api.call('POST', `/api/panels/${panels[0].id}/mode`, { mode: 'manual' }), 'manual mode');
  const creds = credentials();
  try {
    for (const role of ['operator', 'supervisor', 'administrator']) {
      const b = await launch(`20-header-${role}`);
      const page = b.page;
      try {
        await login(page, creds[role].user, creds[role].password);
        await page.locator('#mode-light:not([hidden])').waitFor();
        for (const [w, hgt] of [[1366, 768], [1920, 1080]]) {
          await page.setViewportSize({ width: w, height: hgt });
          await page.waitForTimeout(200);
          const rows = await headerRows(page);
          await b.screenshot(`${w}`);
          assert.ok(rows.height <= 52 && rows.spread <= 6,
            `${role} at ${w}x${hgt}: the header is ${rows.height} px high, its ${rows.count} items spread over ${rows.spread} px`);
        }
        // At 1920 px the group button also names the screen on view: its name is still its words (axe).
        await page.goto(`${BASE}/#/${DRAWN.length ? `custom:${DRAWN[0]}` : 'main'}`);
        await page.locator('#toolbar .tool-menu-button.tool-here').waitFor();
        assert.match(await page.locator('#toolbar .tool-menu-button.tool-here').textContent(), /Process.*Feeder overview 1/);
        assert.deepEqual(seriousFindings(await runAxe(page)).map((v) => `${v.id}: ${v.nodes.join(', ')}`), [],
          `${role}: axe at 1920 px with the group naming the screen`);
        await page.setViewportSize({ width: 1366, height: 768 });
        // Every screen the session allows is in the navigation, and opens from it.
        const session = requireOk(await page.evaluate(async () => {
          const r = await fetch('/api/session'); return { status: r.status, body: await r.json() };
        }), 'session');
        const inNav = await page.locator('#toolbar a[data-screen]').evaluateAll((as) => as.map((a) => a.dataset.screen));
        const catalog = requireOk(await api.call('GET', '/api/screens'), 'catalog').screens.map((s) => s.id);
        const expected = catalog.filter((id) => session.screens.includes(id));
        assert.deepEqual([...inNav].sort(), [...expected].sort(), `${role}: the navigation lists the screens the session allows`);
        for (const id of [expected.find((x) => x.startsWith('custom:')), 'alarms', expected.at(-1)].filter(Boolean)) {
          await openFromNavigation(page, id);
        }
        // The group holding the current screen says so, and its list is closed again.
        const here = await page.locator('#toolbar .tool-here, #toolbar a[aria-current="page"]')
          .evaluateAll((es) => es.filter((e) => e.getBoundingClientRect().width > 0).length);
        assert.equal(here, 1, 'one place in the header marks the current screen');
        assert.equal(await page.locator('#toolbar .tool-open').count(), 0, 'no list stays open after a choice');

        // By keyboard: the Process group opens with Enter, arrows move, Escape closes back to its button.
        const process = page.locator('#toolbar button.tool-menu-button[data-group="process"]');
        await process.focus();
        await page.keyboard.press('Enter');
        assert.equal(await process.getAttribute('aria-expanded'), 'true');
        await page.keyboard.press('Escape');
        assert.equal(await process.getAttribute('aria-expanded'), 'false');
        await process.press('ArrowDown');
        const focused = await page.evaluate(() => document.activeElement.dataset.screen);
        assert.ok(focused, 'ArrowDown moves into the list');
        await page.keyboard.press('ArrowDown');
        const second = await page.evaluate(() => document.activeElement.dataset.screen);
        await page.keyboard.press('Enter');
        await until(`the keyboard opened ${second}`, async () => page.url().endsWith(`#/${second}`), 5_000);
        // A click elsewhere closes an open list.
        await process.click();
        await page.locator('#screen').click({ position: { x: 5, y: 5 } });
        assert.equal(await process.getAttribute('aria-expanded'), 'false', 'a click outside closes the list');
        assert.deepEqual(b.problems, []);
      } finally {
        await b.close();
      }
    }
  } finally {
    await removeScreens(api);
    await api.call('POST', `/api/panels/${panels[0].id}/mode`, { mode: 'auto' });
  }
});

test('on a 390-px phone the process comes first', async () => {
  const c = credentials().supervisor;
  const b = await launch('20-phone');
  const page = b.page;
  try {
    await page.setViewportSize({ width: 390, height: 844 });
    await login(page, c.user, c.password);
    const main = await page.evaluate(() => {
      const hdr = document.getElementById('header').getBoundingClientRect();
      const foot = document.getElementById('alarm-footer').getBoundingClientRect();
      return { header: Math.round(hdr.height), footer: Math.round(foot.height), process: Math.round(foot.top - hdr.bottom) };
    });
    await b.screenshot('main');
    assert.ok(main.header <= 80, `the header is ${main.header} px high on a phone`);
    assert.ok(main.footer <= 130, `the alarm footer is ${main.footer} px high on a phone`);
    assert.ok(main.process >= 600, `the process gets ${main.process} of 844 px`);
    assert.equal(await page.evaluate(() => document.documentElement.scrollWidth <= window.innerWidth), true, 'no sideways scrolling of the page');

    // One "Screens" button lists every screen under its group's heading.
    const btn = page.locator('#toolbar .tool-phone-button');
    await btn.click();
    assert.equal(await btn.getAttribute('aria-expanded'), 'true');
    const visibleLinks = await page.locator('#toolbar a[data-screen]').evaluateAll((as) => as.filter((a) => a.getBoundingClientRect().width > 0).length);
    const allLinks = await page.locator('#toolbar a[data-screen]').count();
    assert.equal(visibleLinks, allLinks, 'every screen is listed');
    await b.screenshot('screens-open');
    await page.locator('#toolbar a[data-screen="units"]').click();
    assert.equal(await btn.getAttribute('aria-expanded'), 'false', 'a choice closes the list');

    // The unit table: name, P, setpoint and state on the screen, without sideways scrolling.
    await page.locator('#screen table').first().waitFor();
    const clipped = await page.evaluate(() => {
      const table = document.querySelector('#screen table');
      const heads = [...table.querySelectorAll('thead th')].map((th) => ({ text: th.textContent.trim(), r: th.getBoundingClientRect() }));
      return heads.filter((x) => /^(unit|p\b|p |setpoint|state)/i.test(x.text) && x.r.right > window.innerWidth + 1).map((x) => x.text);
    });
    await b.screenshot('units');
    assert.deepEqual(clipped, [], 'the unit table keeps P, setpoint and state on the screen');

    // The microgrid screen's unit table too.
    await page.goto(`${BASE}/#/microgrid`);
    await page.locator('#screen table').first().waitFor();
    const mgClipped = await page.evaluate(() => {
      // Every value an operator acts on, in every unit's row, lies within the screen's width.
      const out = [];
      for (const td of document.querySelectorAll('#mg-units-table td')) {
        const col = td.dataset.label || '';
        if (/^(P|Setpoint|State|SoC)$/.test(col) && td.getBoundingClientRect().right > window.innerWidth + 1) out.push(col);
      }
      return [...new Set(out)];
    });
    await b.screenshot('microgrid');
    assert.deepEqual(mgClipped, [], 'the microgrid screen keeps P, setpoint and state on the screen');

    // The alarm screen shows its summary per area once (the footer gives way to it).
    await page.goto(`${BASE}/#/alarms`);
    await page.locator('#screen table').first().waitFor();
    await page.waitForTimeout(300);
    const summaries = await page.locator('table.alarm-summary').evaluateAll((ts) => ts.filter((t) => t.getBoundingClientRect().height > 0).length);
    await b.screenshot('alarms');
    assert.equal(summaries, 1, 'one summary per area on the alarm screen');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
