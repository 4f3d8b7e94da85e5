// 13. Reports: a Supervisor makes today's report on the Reports screen, opens
// it, and prints it to PDF through Chromium (CDP Page.printToPDF); the PDF's
// text has the report's title (pdftotext) and its first page, turned into an
// image by pdftoppm, is not blank. An Operator has no Reports screen.
// The report reads without the code (issue 33, finding 12): a zone fault's
// alarm, acknowledged, is a top alarm naming its panel (by its configured
// name) and its tag or key; times to acknowledge are in words, not raw
// seconds; every cost carries the configured currency; and the Definitions
// at the end define each figure, the PV and wind share's denominator too.
import test from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { execFileSync } from 'node:child_process';
import { launch, login, credentials, toolbar, adminApi, requireOk, until, BASE, ARTIFACTS } from '../lib.js';
import { restorePanel } from '../fixtures.js';

// A panel and zone no other test of this folder faults.
const PANEL = 'css1';
const ZONE = 3;

/** A duration as the report writes it: "4.2 s", "45 s", "2 min 05 s", "8 h 45 min". */
const DURATION_WORDS = /^(\d(\.\d)? s|[1-5]?\d s|\d+ min \d\d s|\d+ h \d\d min)$/;

/**
 * Faults zone ZONE of PANEL for good, waits for the sequence's alarm of the
 * zone isolated, acknowledges it a little later and restores the panel; returns the alarm.
 */
async function isolatedAndAcknowledged(api) {
  await restorePanel(api, PANEL);
  requireOk(await api.call('POST', '/api/sim/faults', { panel: PANEL, zone: ZONE, kind: 'permanent' }), 'injecting a permanent fault');
  const alarm = await until(`the alarm of ${PANEL} zone ${ZONE} isolated`, async () => {
    const { alarms } = requireOk(await api.call('GET', '/api/alarms'), 'alarms');
    return alarms.find((a) => a.key.endsWith(`zone${ZONE}.isolated`) && a.active && !a.acked && a.selection) || false;
  }, 90_000, 500);
  // The sequence at rest (a reset before is ignored), and a few seconds for
  // the time to acknowledge.
  await until(`${PANEL} at rest with zone ${ZONE} isolated`, async () => {
    const panel = requireOk(await api.call('GET', `/api/panels/${PANEL}`), 'the panel');
    return panel.step === 'isolated';
  }, 60_000, 500);
  await new Promise((r) => setTimeout(r, 2_500));
  requireOk(await api.call('POST', '/api/alarms/ack', { ids: [alarm.id] }), 'acknowledging the alarm');
  await restorePanel(api, PANEL);
  return alarm;
}

/** Mean and share of dark pixels of a binary PGM (P5, 8-bit) image. */
function pgmStats(file) {
  const buf = fs.readFileSync(file);
  // Header: P5 <w> <h> <max>, whitespace separated, then the pixels.
  let pos = 0;
  const fields = [];
  while (fields.length < 4) {
    while (/\s/.test(String.fromCharCode(buf[pos]))) pos += 1;
    let start = pos;
    while (!/\s/.test(String.fromCharCode(buf[pos]))) pos += 1;
    fields.push(buf.subarray(start, pos).toString());
  }
  pos += 1;
  const [magic, w, h] = [fields[0], Number(fields[1]), Number(fields[2])];
  assert.equal(magic, 'P5');
  const px = buf.subarray(pos, pos + w * h);
  let sum = 0;
  let dark = 0;
  for (const v of px) { sum += v; if (v < 128) dark += 1; }
  return { w, h, mean: sum / px.length, dark: dark / px.length };
}

test('a supervisor makes, opens and prints a report; an operator has no reports screen', async () => {
  const c = credentials();
  const api = await adminApi();
  const alarm = await isolatedAndAcknowledged(api);
  const panelName = requireOk(await api.call('GET', `/api/panels/${PANEL}`), 'the panel').name;
  assert.ok(panelName, 'the panel has a configured name');
  const b = await launch('13-reports');
  const page = b.page;
  try {
    await login(page, c.operator.user, c.operator.password);
    assert.ok(!(await toolbar(page)).includes('reports'), 'no Reports screen for an Operator');
  } finally {
    await b.close();
  }

  const s = await launch('13-reports');
  try {
    const p = s.page;
    await login(p, c.supervisor.user, c.supervisor.password);
    assert.ok((await toolbar(p)).includes('reports'), 'a Supervisor has the Reports screen');
    await p.goto(`${BASE}/#/reports`);
    const today = new Date().toISOString().slice(0, 10);
    await p.locator('#reports-day').fill(today);
    await p.locator('#reports-make').click();
    await p.locator('#reports-status', { hasText: `Report ${today} made` }).waitFor();
    // The schedule may have made yesterday's and last month's already.
    const row = p.locator('#reports-table tbody tr').filter({ has: p.locator('td:first-child', { hasText: new RegExp(`^${today}$`) }) });
    await row.waitFor();
    await s.screenshot('listed');
    const href = await row.locator('a', { hasText: 'Open' }).getAttribute('href');
    const download = await row.locator('a', { hasText: 'CSV' }).getAttribute('href');
    assert.match(download, /\/api\/reports\/\d{4}-\d\d-\d\d\/csv\?download=1$/);

    const json = requireOk(await api.call('GET', `/api/reports/${today}/json`), 'the report as JSON');
    const currency = json.currency;
    assert.match(String(currency), /^[A-Z]{3}$/, 'the report carries the configured currency ([reports] currency)');

    await p.goto(href);
    await p.locator('h1', { hasText: `Daily report ${today}` }).waitFor();
    await s.screenshot('report');

    // The top alarm names where it is and what: "PANEL NAME · TAG OR KEY — MESSAGE".
    const where = `${panelName} · ${alarm.tag || alarm.key} — ${alarm.message}`;
    const topRows = await p.locator('table#top-alarms tr td:first-child').allTextContents();
    assert.ok(topRows.includes(where), `a top alarm reads "${where}": ${JSON.stringify(topRows)}`);
    // Times to acknowledge in words an operator reads, not raw seconds.
    const ackCells = await p.locator('tr', { has: p.locator('th', { hasText: /^Time to acknowledge/ }) }).locator('td').allTextContents();
    assert.ok(ackCells.length >= 4, `times to acknowledge shown: ${JSON.stringify(ackCells)}`);
    for (const t of ackCells) assert.match(t.trim(), DURATION_WORDS, `a time to acknowledge in words: "${t}"`);
    // Every cost carries the currency.
    const costCells = await p.locator('table').evaluateAll((tables) => {
      const out = [];
      for (const t of tables) {
        const heads = [...t.querySelectorAll('tr:first-child th')].map((th) => th.textContent.trim());
        const col = heads.indexOf('Cost');
        if (col >= 0) for (const tr of [...t.querySelectorAll('tr')].slice(1)) out.push(tr.children[col]?.textContent.trim());
        for (const tr of t.querySelectorAll('tr')) if (tr.firstElementChild?.textContent.trim() === 'Cost') out.push(tr.children[1]?.textContent.trim());
      }
      return out;
    });
    assert.ok(costCells.length >= 2, `costs shown: ${JSON.stringify(costCells)}`);
    for (const t of costCells) assert.match(t, new RegExp(`^(-?\\d+\\.\\d\\d ${currency}|—)$`), `a cost in ${currency}: "${t}"`);
    // The Definitions define every figure printed, in the code's terms.
    const defined = await p.locator('#definitions + dl dt').allTextContents();
    for (const figure of ['Data', 'Panel kWh', 'kWh out', 'kWh in', 'Run time', 'Fuel l', 'Cycles', 'Cost', 'Demand kWh',
      'Produced kWh', 'PV and wind share', 'Activations', 'Acknowledged', 'Time to acknowledge', 'Top alarms',
      'Sustained, Momentary', 'SAIFI, SAIDI, MAIFI', 'ENS kWh']) {
      assert.ok(defined.includes(figure), `"${figure}" is defined: ${JSON.stringify(defined)}`);
    }
    const share = await p.locator('#definitions + dl dt', { hasText: /^PV and wind share$/ }).locator('xpath=following-sibling::dd[1]').textContent();
    assert.match(share, /Battery discharge is in the denominator/);
    assert.match(await p.locator('#definitions + dl').textContent(), new RegExp(`in ${currency}`));
    await p.locator('#definitions').scrollIntoViewIfNeeded();
    await s.screenshot('definitions');
    fs.mkdirSync(ARTIFACTS, { recursive: true });
    const pdf = path.join(ARTIFACTS, '13-reports.pdf');
    const cdp = await p.context().newCDPSession(p);
    const printed = await cdp.send('Page.printToPDF', { printBackground: true, paperWidth: 8.27, paperHeight: 11.69 });
    fs.writeFileSync(pdf, Buffer.from(printed.data, 'base64'));
    const text = execFileSync('pdftotext', ['-layout', pdf, '-'], { encoding: 'utf8' });
    assert.match(text, new RegExp(`Daily report ${today}`), 'the PDF has the title');
    assert.match(text, /Energy/);
    assert.match(text, /Outages/);
    assert.match(text, /Definitions/, 'the PDF has the Definitions');
    // In reading order (no -layout), so a table cell wrapped over lines reads as one.
    const flowing = execFileSync('pdftotext', [pdf, '-'], { encoding: 'utf8' }).replace(/\s+/g, ' ');
    assert.ok(flowing.includes(`${panelName} · ${alarm.tag || alarm.key}`), `the PDF names the top alarm's panel and tag: ${flowing}`);
    const stem = path.join(ARTIFACTS, '13-reports-page');
    execFileSync('pdftoppm', ['-f', '1', '-l', '1', '-r', '50', '-png', '-singlefile', pdf, stem]);
    assert.ok(fs.statSync(`${stem}.png`).size > 1000, 'page 1 as PNG');
    execFileSync('pdftoppm', ['-f', '1', '-l', '1', '-r', '50', '-gray', '-singlefile', pdf, stem]);
    const st = pgmStats(`${stem}.pgm`);
    assert.ok(st.mean < 254 && st.dark > 0.003 && st.dark < 0.5, `page 1 is not blank: ${JSON.stringify(st)}`);
    assert.deepEqual(s.problems, [], 'no script error or CSP violation');
  } finally {
    await s.close();
  }
});
