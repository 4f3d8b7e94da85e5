// 13. Reports: a Supervisor makes today's report on the Reports screen, opens
// it, and prints it to PDF through Chromium (CDP Page.printToPDF); the PDF's
// text has the report's title (pdftotext) and its first page, turned into an
// image by pdftoppm, is not blank. An Operator has no Reports screen.
import test from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { execFileSync } from 'node:child_process';
import { launch, login, credentials, toolbar, BASE, ARTIFACTS } from '../lib.js';

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

    await p.goto(href);
    await p.locator('h1', { hasText: `Daily report ${today}` }).waitFor();
    await s.screenshot('report');
    fs.mkdirSync(ARTIFACTS, { recursive: true });
    const pdf = path.join(ARTIFACTS, '13-reports.pdf');
    const cdp = await p.context().newCDPSession(p);
    const printed = await cdp.send('Page.printToPDF', { printBackground: true, paperWidth: 8.27, paperHeight: 11.69 });
    fs.writeFileSync(pdf, Buffer.from(printed.data, 'base64'));
    const text = execFileSync('pdftotext', ['-layout', pdf, '-'], { encoding: 'utf8' });
    assert.match(text, new RegExp(`Daily report ${today}`), 'the PDF has the title');
    assert.match(text, /Energy/);
    assert.match(text, /Outages/);
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
