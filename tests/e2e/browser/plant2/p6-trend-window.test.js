// The trend's window (issue 15 #4): turning Live off keeps the window that
// was on view (never one reaching into the future), and a start date and
// time typed in stays and sets the window.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until, BASE } from '../lib.js';

const pad = (n) => String(n).padStart(2, '0');
const dateValue = (d) => `${d.getFullYear()}-${pad(d.getMonth() + 1)}-${pad(d.getDate())}`;
const timeValue = (d) => `${pad(d.getHours())}:${pad(d.getMinutes())}:${pad(d.getSeconds())}`;

test('trend: Live off keeps the window; a typed start date and time sets it', async () => {
  const api = await adminApi();
  const { tags } = requireOk(await api.call('GET', '/api/tags?search=.PA.V_L1&limit=5'), 'tags');
  const pen = tags[0].name;
  const c = credentials().operator;
  const b = await launch('p6-trend');
  const page = b.page;
  const fields = async () => new Date(`${await page.locator('#trend-start-date').inputValue()}T${await page.locator('#trend-start-time').inputValue()}`).getTime();
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/trends?pens=${pen}`);
    await page.locator(`#trend-pens li[data-pen="${pen}"]`).waitFor();
    await page.locator('#trend-status', { hasText: '(live)' }).waitFor();
    const duration = Number(await page.locator('#trend-duration').inputValue()) * 1000;

    // Live off: the window shown stays, and it ends no later than now.
    await page.locator('#trend-live').uncheck();
    await until('the frozen window is loaded', async () => !/live|Loading/.test(await page.locator('#trend-status').textContent()));
    const start = await fields();
    assert.ok(start + duration <= Date.now() + 1000, `the window ends in the past: ${new Date(start + duration).toISOString()}`);
    assert.ok(start >= Date.now() - duration - 20_000, 'it is the window that was on view');

    // A start typed in is kept, and the window starts there.
    const wanted = new Date(start - 5 * 60_000);
    await page.locator('#trend-start-time').fill(timeValue(wanted));
    await page.locator('#trend-start-time').dispatchEvent('change');
    await page.locator('#trend-start-date').fill(dateValue(wanted));
    await page.locator('#trend-start-date').dispatchEvent('change');
    const label = `${dateValue(wanted)} ${timeValue(wanted)} to`;
    await page.locator('#trend-status', { hasText: label }).waitFor({ timeout: 5000 });
    await page.waitForTimeout(1500);
    assert.equal(await page.locator('#trend-start-time').inputValue(), timeValue(wanted), 'the typed time stays');
    assert.equal(await page.locator('#trend-start-date').inputValue(), dateValue(wanted), 'the typed date stays');
    assert.equal(await page.locator('#trend-live').isChecked(), false);
    assert.match(await page.locator('#trend-status').textContent(), new RegExp(label));
    await b.screenshot('typed-window');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
