// CSV downloads (issue 20): the event screen's Download CSV gives the rows
// its filter selects, with no row cap; the alarm history's and the
// microgrid's dispatch download links carry their screens' filters.
import test from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import { launch, login, credentials, until } from '../lib.js';

test('the event, alarm history and dispatch screens download CSV', async () => {
  const c = credentials().supervisor;
  const b = await launch('13-exports');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    const base = page.url().split('#')[0];
    await page.goto(`${base}#/events`);
    await page.locator('#events-table').waitFor();
    await page.locator('#events-type').fill('login');
    await page.locator('#events-search').click();
    await until('the link carries the filter', async () => /type=login/.test(await page.locator('#events-csv').getAttribute('href')));
    const [download] = await Promise.all([page.waitForEvent('download'), page.locator('#events-csv').click()]);
    assert.equal(download.suggestedFilename(), 'events.csv');
    const lines = fs.readFileSync(await download.path(), 'utf8').trim().split('\n');
    assert.equal(lines[0], 'time_utc,ts_ms,user,source,type,message');
    assert.ok(lines.length >= 2, 'at least this login');
    assert.ok(lines.slice(1).every((l) => l.split(',')[4] === 'login'), lines.join('\n'));
    assert.ok(lines.some((l) => l.split(',')[2] === c.user), `${c.user}'s login is in the file`);

    await page.goto(`${base}#/alarms`);
    await page.locator('#alarms-tab-history').click();
    await page.locator('#hist-selection').fill('SS1');
    await page.locator('#hist-search').click();
    await until('the history link carries the filter', async () => /selection=SS1/.test(await page.locator('#hist-csv').getAttribute('href') || ''));
    const hist = await page.evaluate((href) => fetch(href).then(async (r) => ({ status: r.status, type: r.headers.get('content-type'), text: await r.text() })),
      await page.locator('#hist-csv').getAttribute('href'));
    assert.equal(hist.status, 200);
    assert.match(hist.type, /^text\/csv/);
    assert.match(hist.text, /^time_utc,ts_ms,alarm,tag,kind,from_state,to_state,cause/);

    await page.goto(`${base}#/microgrid`);
    const href = await until('the dispatch download', async () => page.locator('#dispatch-csv').getAttribute('href').catch(() => null), 30_000);
    const disp = await page.evaluate((u) => fetch(u).then((r) => r.text()), href);
    assert.match(disp, /^time_utc,ts_ms,status,mode,objective,solve_ms,reason,setpoints\n/);
    await b.screenshot('events-download');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
