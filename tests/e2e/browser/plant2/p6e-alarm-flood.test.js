// A flood of standing alarms in the HMI (issue 34): the footer draws the top
// of the list and counts the rest, the Alarms screen draws a page at a time
// and "Show more" adds the next. The flood is handed to the page's live feed
// as the server's whole list comes (the server side of a flood is tested in
// the web crate); the draw times are printed, beside drawing every row as
// the HMI did before (as the footer's Print still does), in the same page.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials } from '../lib.js';

const FLOOD = 40_000;

test('a flood of standing alarms: the footer draws the top, the Alarms screen pages through', async () => {
  const c = credentials().operator;
  const b = await launch('p6e-alarm-flood');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${page.url().split('#')[0]}#/alarms`);
    await page.locator('#alarms-online').waitFor();
    // Everything below runs in one task, so no server message comes between
    // the flood and the checks.
    const r = await page.evaluate(async (n) => {
      const base = document.baseURI;
      const { live } = await import(new URL('js/live.js', base).href);
      const { sortAlarms } = await import(new URL('js/components/alarmtable.js', base).href);
      const now = Date.now();
      const alarms = Array.from({ length: n }, (_, i) => ({
        id: 1_000_000 + i, key: `flood.${i}`, tag: `flood.t${i}`, message: `Flood alarm ${i}`,
        priority: [200, 400, 600, 800][i % 4], selection: `Area ${i % 7}`, kind: 'hi',
        state: i % 3 ? 'unack_active' : 'ack_active', acked: i % 3 === 0, active: true,
        last_change: now - i, activated_at: now - i, value: i, units: 'V', limit: 1,
      }));
      const rows = (sel) => document.querySelectorAll(`${sel} tr.alarm-row`).length;
      const t0 = performance.now();
      live.handle(JSON.stringify({ type: 'alarms', version: live.alarmVersion, alarms }));
      void document.body.offsetHeight; // layout included
      const drawMs = performance.now() - t0;
      const out = {
        drawMs,
        footerRows: rows('#footer-alarms'),
        footerTop: Number(document.querySelector('#footer-alarms tr.alarm-row').dataset.alarmId),
        expectedTop: sortAlarms(alarms)[0].id,
        footerMore: document.querySelector('#footer-alarms tr.alarm-more')?.textContent || '',
        footerCount: document.querySelector('#footer-count').textContent,
        screenRows: rows('#alarms-online'),
        screenCount: document.querySelector('#alarms-count').textContent,
        moreButton: document.querySelector('#alarms-more')?.textContent || '',
      };
      document.querySelector('#alarms-more').click();
      out.screenRowsAfterMore = rows('#alarms-online');
      // Print puts the whole list into the footer for the printout: every
      // row drawn, as the footer drew them at every change before (the peer).
      window.print = () => { void document.body.offsetHeight; out.printedRows = rows('#footer-alarms'); };
      const t1 = performance.now();
      document.querySelector('#footer-print').click();
      out.everyRowMs = performance.now() - t1;
      return out;
    }, FLOOD);
    console.log(`alarm flood of ${FLOOD}: footer and Alarms screen drawn in ${r.drawMs.toFixed(0)} ms; `
      + `every row, as before (Print) ${r.everyRowMs.toFixed(0)} ms`);
    assert.equal(r.footerRows, 100, 'the footer draws the top 100 rows');
    assert.equal(r.footerTop, r.expectedTop, 'the footer\'s top row is the list\'s top');
    assert.match(r.footerMore, /39900 more alarms below these 100/);
    assert.match(r.footerCount, /^40000 shown/);
    assert.equal(r.screenRows, 500, 'the Alarms screen draws a page');
    assert.match(r.screenCount, /^40000 of 40000 alarms/);
    assert.match(r.moreButton, /Show 500 more/);
    assert.equal(r.screenRowsAfterMore, 1000, 'Show more adds a page');
    assert.equal(r.printedRows, FLOOD, 'Print prints the whole list');
    await page.waitForFunction(() => document.querySelectorAll('#footer-alarms tr.alarm-row').length <= 100, null, { timeout: 30_000 });
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
