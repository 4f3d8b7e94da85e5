// The alarm footer (issue 15 #14): resized by dragging its top edge (or the
// arrow keys), the height kept for the session; on a phone it shows the
// alarm counts by priority for each area instead of rows, and an area opens
// its rows. The alarm screen has the same summary per area.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until, BASE } from '../lib.js';
import { restorePanel } from '../fixtures.js';

const PANEL = 'css1';
const band = (p) => (p >= 800 ? 'urgent' : p >= 600 ? 'high' : p >= 400 ? 'medium' : 'low');

/** The footer summary as shown: {selection: {urgent, high, medium, low, unacked, total}}. */
async function shownSummary(page, id) {
  return page.locator(`#${id} tbody tr[data-selection]`).evaluateAll((rows) => Object.fromEntries(rows.map((r) => {
    const n = (k) => Number((r.querySelector(`td[data-band="${k}"]`) || {}).textContent.replace(/\D/g, '') || 0);
    const tds = r.querySelectorAll('td');
    return [r.dataset.selection, { urgent: n('urgent'), high: n('high'), medium: n('medium'), low: n('low'), unacked: Number(tds[4].textContent), total: Number(tds[5].textContent) }];
  })));
}

/** The same counts from the server's standing alarms. */
async function serverSummary(api) {
  const { alarms } = requireOk(await api.call('GET', '/api/alarms'), 'alarms');
  const out = {};
  for (const a of alarms) {
    const r = (out[a.selection] ||= { urgent: 0, high: 0, medium: 0, low: 0, unacked: 0, total: 0 });
    r[band(a.priority)] += 1;
    r.total += 1;
    if (!a.acked) r.unacked += 1;
  }
  return out;
}

test('alarm footer: resizable and remembered; a summary per area on a phone', async () => {
  const api = await adminApi();
  await restorePanel(api, PANEL);
  const c = credentials().operator;
  const b = await launch('12-footer');
  const page = b.page;
  const footerH = () => page.locator('#alarm-footer').evaluate((e) => Math.round(e.getBoundingClientRect().height));
  try {
    await login(page, c.user, c.password);
    await page.locator('#footer-alarms').waitFor();
    // Alarms standing: a zone isolated.
    requireOk(await api.call('POST', '/api/sim/faults', { panel: PANEL, zone: 3, kind: 'permanent' }), 'injecting a fault');
    await page.locator('#footer-alarms tr.alarm-row').first().waitFor({ timeout: 30_000 });

    // Drag the top edge up by 200 px: the footer grows by as much, and shows more rows' room.
    const h0 = await footerH();
    const grip = await page.locator('#footer-resize').boundingBox();
    await page.mouse.move(grip.x + grip.width / 2, grip.y + grip.height / 2);
    await page.mouse.down();
    await page.mouse.move(grip.x + grip.width / 2, grip.y + grip.height / 2 - 100, { steps: 4 });
    await page.mouse.move(grip.x + grip.width / 2, grip.y + grip.height / 2 - 200, { steps: 4 });
    await page.mouse.up();
    const h1 = await footerH();
    assert.ok(Math.abs(h1 - (h0 + 200)) <= 4, `dragged from ${h0} to ${h1} px`);
    // The screen's content keeps clear of it.
    const pad = await page.locator('#screen').evaluate((e) => parseFloat(getComputedStyle(e).paddingBottom));
    assert.ok(pad >= h1, `the content's bottom padding ${pad} clears the footer ${h1}`);
    await b.screenshot('footer-taller');

    // The keyboard: the separator takes the arrow keys.
    await page.locator('#footer-resize').focus();
    await page.keyboard.press('ArrowDown');
    await page.keyboard.press('ArrowDown');
    const h2 = await footerH();
    assert.equal(h2, h1 - 40, 'two steps down');
    assert.equal(await page.locator('#footer-resize').getAttribute('aria-valuenow'), String(h2));

    // Kept for the session: a reload, another screen.
    await page.reload();
    await page.locator('#footer-alarms').waitFor();
    await until('the height restored', async () => (await footerH()) === h2, 5000, 100);
    await page.goto(`${BASE}/#/events`);
    await page.locator('#events-search').waitFor();
    assert.equal(await footerH(), h2, 'the same height on another screen');
    // Never above most of the window, never below the bar.
    await page.locator('#footer-resize').focus();
    await page.keyboard.press('Home');
    assert.ok((await footerH()) <= 768 * 0.8 + 1, 'at most 80 % of the window');
    await page.keyboard.press('End');
    assert.ok((await footerH()) >= 60, 'at least its bar');
    for (let i = 0; i < 7; i++) await page.keyboard.press('ArrowUp');

    // The alarm screen: the summary per area agrees with the server.
    await page.goto(`${BASE}/#/alarms`);
    await page.locator('#alarms-summary-table tbody tr[data-selection]').first().waitFor();
    await until('the alarm screen summary matches the server', async () =>
      JSON.stringify(await shownSummary(page, 'alarms-summary-table')) === JSON.stringify(await serverSummary(api)), 10_000, 300);
    // An area filters the list.
    const area = Object.keys(await shownSummary(page, 'alarms-summary-table'))[0];
    await page.locator(`#alarms-summary-table tr[data-selection="${area}"] button`).click();
    assert.equal(await page.locator('#alarms-selection').inputValue(), area);

    // A phone: the footer shows the counts by priority per area instead of rows.
    await page.setViewportSize({ width: 390, height: 844 });
    await page.goto(`${BASE}/#/main`);
    await page.locator('#footer-summary-table').waitFor();
    assert.equal(await page.locator('#footer-alarms').isVisible(), false, 'no rows on a phone');
    await until('the footer summary matches the server', async () =>
      JSON.stringify(await shownSummary(page, 'footer-summary-table')) === JSON.stringify(await serverSummary(api)), 10_000, 300);
    const inView = await page.evaluate(() => {
      const f = document.getElementById('alarm-footer').getBoundingClientRect();
      const r = document.querySelector('#footer-summary-table tbody tr').getBoundingClientRect();
      return r.height > 0 && r.top >= f.top && r.bottom <= f.bottom;
    });
    assert.ok(inView, 'the first area is in view in the footer');
    const phoneWidth = await page.evaluate(() => document.documentElement.scrollWidth);
    assert.ok(phoneWidth <= 390, `no sideways scroll of the page: ${phoneWidth}`);
    await b.screenshot('phone-summary');
    // An area opens its rows.
    await page.locator(`#footer-summary-table tr[data-selection="${area}"] button`).click();
    await page.locator('#footer-alarms').waitFor();
    assert.equal(await page.locator('#footer-selection').inputValue(), area);
    await b.screenshot('phone-rows');
    await page.locator('#footer-view').click();
    await page.locator('#footer-summary-table').waitFor();
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await restorePanel(api, PANEL).catch(() => {});
  }
});
