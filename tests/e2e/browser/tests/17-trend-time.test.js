// Time on the trend screen (issue 33, finding 8): the start time is typed
// and shown as 24-hour time whatever the browser's locale; the time axis
// ticks fall on round intervals of the clock, evenly spaced; the status
// line says how much time one drawn point stands for, not "buckets".
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, BASE } from '../lib.js';

test('trend time: 24-hour start time, round ticks, the status in an operator\'s words', async () => {
  const c = credentials().operator;
  const b = await launch('17-trend-time', { locale: 'en-US' });
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/trends?pens=SS1.PA.V_L1`);
    const time = page.locator('#trend-start-time');
    await time.waitFor();
    // The browser runs in a 12-hour locale (en-US); the field is still 24-hour.
    assert.match(await page.evaluate(() => new Date(2026, 0, 1, 14, 5).toLocaleTimeString()), /^2:05:00\s?PM$/u, 'the browser\'s own locale is 12-hour');
    assert.notEqual(await time.getAttribute('type'), 'time', 'not a locale-following time input');
    assert.match(await time.inputValue(), /^([01]\d|2[0-3]):[0-5]\d:[0-5]\d$/, '24-hour HH:MM:SS');
    // The status line: samples and the time one point stands for, no "buckets".
    const status = page.locator('#trend-status');
    await status.filter({ hasText: 'samples' }).waitFor({ timeout: 15_000 });
    const text = await status.textContent();
    assert.doesNotMatch(text, /bucket/i, text);
    assert.match(text, /one point every \d+ (ms|s|min|h)\b/, text);
    // A 12-hour time is refused with words; a 24-hour one is taken.
    await time.fill('2:05 PM');
    await time.dispatchEvent('change');
    await status.filter({ hasText: '24-hour' }).waitFor({ timeout: 5_000 });
    await time.fill('14:05:00');
    await time.dispatchEvent('change');
    await status.filter({ hasText: 'samples' }).waitFor({ timeout: 15_000 });
    assert.equal(await time.inputValue(), '14:05:00');

    // Ticks: 15 minutes on a plot with room for 10 labels → every 2 minutes, on the minute.
    const ticks = await page.evaluate(async () => {
      const { timeTicks } = await import('/js/components/chart.js');
      const out = [];
      for (const [span, max] of [[15 * 60_000, 10], [5 * 60_000, 8], [24 * 3_600_000, 9], [7 * 86_400_000, 8], [60_000, 6]]) {
        const from = Date.UTC(2026, 10, 29, 9, 22, 38, 417);
        const { step, times } = timeTicks(from, from + span, max);
        const local = times.map((t) => { const d = new Date(t); return [d.getHours(), d.getMinutes(), d.getSeconds(), d.getMilliseconds()]; });
        out.push({ span, max, step, n: times.length, gaps: [...new Set(times.slice(1).map((t, i) => t - times[i]))], local, inside: times.every((t) => t >= from && t <= from + span) });
      }
      return out;
    });
    for (const t of ticks) {
      assert.ok(t.n >= 2 && t.n <= t.max + 1, `${t.span} ms: ${t.n} ticks for room of ${t.max}`);
      assert.deepEqual(t.gaps, [t.step], `${t.span} ms: evenly spaced`);
      assert.ok(t.inside, `${t.span} ms: inside the window`);
      for (const [h, m, s, ms] of t.local) {
        const sinceMidnight = ((h * 60 + m) * 60 + s) * 1000 + ms;
        assert.equal(sinceMidnight % Math.min(t.step, 86_400_000), 0, `${t.span} ms: ${h}:${m}:${s}.${ms} is a whole multiple of ${t.step} ms on the clock`);
      }
    }
    assert.equal(ticks[0].step, 2 * 60_000, '15 minutes: a tick every 2 minutes');
    await b.screenshot('trend-time');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
