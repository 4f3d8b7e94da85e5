// The plant's date order (`[hmi] date_format`; issue 33, finding 8): the
// clock, the trend's start date field, its status line and its cursor, the
// event log's date fields and the alarm history's time fields follow it,
// and a date typed in that order is taken. The demo keeps the default
// (YYYY-MM-DD): here the session's setting is replaced on its way
// to the browser by the one a DD.MM.YYYY plant sends; the server's side
// (the key, its check, GET /api/session) has its Rust tests.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, until, BASE } from '../lib.js';

const DATE = /^\d{2}\.\d{2}\.\d{4} ([01]\d|2[0-3]):[0-5]\d:[0-5]\d$/;

/** Answers the page's GET /api/session as a plant with `[hmi] date_format = "DD.MM.YYYY"` does. */
async function asDayFirstPlant(page) {
  await page.route('**/api/session', async (route) => {
    if (route.request().method() !== 'GET') { await route.continue(); return; }
    const resp = await route.fetch();
    const body = await resp.json();
    body.hmi = { ...body.hmi, date_format: 'DD.MM.YYYY' };
    await route.fulfill({ response: resp, json: body });
  });
}

test('dates in the plant\'s order: DD.MM.YYYY, times 24-hour', async () => {
  const c = credentials().operator;
  const b = await launch('20-date-format', { locale: 'en-US' });
  const page = b.page;
  try {
    await asDayFirstPlant(page);
    await login(page, c.user, c.password);
    await until('the clock in the plant\'s order', async () => DATE.test((await page.locator('#clock').textContent()).trim()), 5_000);

    await page.goto(`${BASE}/#/trends?pens=SS1.PA.V_L1`);
    const date = page.locator('#trend-start-date');
    await date.waitFor();
    assert.notEqual(await date.getAttribute('type'), 'date', 'not a locale-following date input (MM/DD/YYYY in en-US)');
    assert.match(await date.inputValue(), /^\d{2}\.\d{2}\.\d{4}$/, 'the start date in the plant\'s order');
    const status = page.locator('#trend-status');
    await status.filter({ hasText: 'samples' }).waitFor({ timeout: 15_000 });
    assert.match(await status.textContent(), /^\d{2}\.\d{2}\.\d{4} \d\d:\d\d:\d\d to \d{2}\.\d{2}\.\d{4} /, 'the status line');

    // A date typed in that order is taken; one in another order is refused in words.
    const today = new Date();
    const pad = (n) => String(n).padStart(2, '0');
    const typed = `${pad(today.getDate())}.${pad(today.getMonth() + 1)}.${today.getFullYear()}`;
    await date.fill(`${today.getFullYear()}-${pad(today.getMonth() + 1)}-${pad(today.getDate())}`);
    await date.dispatchEvent('change');
    await status.filter({ hasText: 'DD.MM.YYYY' }).waitFor({ timeout: 5_000 });
    await date.fill(typed);
    await page.locator('#trend-start-time').fill('00:00:00');
    await date.dispatchEvent('change');
    await status.filter({ hasText: 'samples' }).waitFor({ timeout: 15_000 });
    assert.ok((await status.textContent()).startsWith(`${typed} 00:00:00 to `), await status.textContent());
    assert.equal(await date.inputValue(), typed, 'the typed date stays');

    // The time axis's day labels (a window of days) and the cursor's time.
    const labels = await page.evaluate(async () => {
      const fmt = await import('/js/format.js');
      const d = new Date(2026, 10, 21, 14, 5, 3);
      return { time: fmt.fmtTime(d.getTime()), short: fmt.fmtDate(d, { year: false }) };
    });
    assert.deepEqual(labels, { time: '21.11.2026 14:05:03', short: '21.11' });
    await b.screenshot('trend-dates');

    // The event log's dates and the alarm history's times: typed in the plant's order too.
    await page.goto(`${BASE}/#/events`);
    const from = page.locator('#events-from');
    await from.waitFor();
    assert.equal(await from.inputValue(), typed, 'today, in the plant\'s order');
    await page.locator('#events-search').click();
    await page.locator('#events-count').waitFor({ timeout: 10_000 });
    assert.match(await page.locator('#events-table tbody td').first().textContent(), DATE, 'the event times');
    // A date in another order does not pass the field's pattern: the form is not sent.
    await from.fill(`${today.getFullYear()}-${pad(today.getMonth() + 1)}-${pad(today.getDate())}`);
    assert.equal(await from.evaluate((i) => i.validity.patternMismatch), true, 'YYYY-MM-DD is refused');
    assert.equal(await from.getAttribute('placeholder'), 'DD.MM.YYYY');
    await page.goto(`${BASE}/#/alarms`);
    await page.locator('#alarms-tab-history').click();
    const histFrom = page.locator('#hist-from');
    await histFrom.waitFor();
    assert.match(await histFrom.inputValue(), DATE, 'the history\'s start, in the plant\'s order');
    await page.locator('#hist-search').click();
    await page.locator('#alarms-history').waitFor({ timeout: 10_000 });
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});

test('the reports screen takes its day in the plant\'s order', async () => {
  const c = credentials().supervisor;
  const b = await launch('20-date-format-reports', { locale: 'en-US' });
  const page = b.page;
  try {
    await asDayFirstPlant(page);
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/reports`);
    const day = page.locator('#reports-day');
    await day.waitFor();
    // Yesterday's UTC day, written DD.MM.YYYY.
    const y = new Date(Date.now() - 86_400_000);
    const p2 = (n) => String(n).padStart(2, '0');
    assert.equal(await day.inputValue(), `${p2(y.getUTCDate())}.${p2(y.getUTCMonth() + 1)}.${y.getUTCFullYear()}`);
    assert.equal(await day.getAttribute('placeholder'), 'DD.MM.YYYY');
    // The ISO order is not this plant's: refused, nothing is made.
    await day.fill(`${y.getUTCFullYear()}-${p2(y.getUTCMonth() + 1)}-${p2(y.getUTCDate())}`);
    assert.equal(await day.evaluate((i) => i.validity.patternMismatch), true, 'YYYY-MM-DD does not match the field');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
