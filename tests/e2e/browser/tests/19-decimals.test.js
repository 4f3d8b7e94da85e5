// Numbers with the decimals their tag is configured with (issue 33, finding
// 7; docs/HMI_STYLE.md rule 9): the demo gives no decimals to its voltages,
// currents and powers (the plant's `[hmi] decimals = 1`), 2 to power factor
// and frequency, 0 to the energy counter. Each shows that count on every
// screen, whatever its size (not 230.1 V beside 42.50 A), and the tag
// browser shows the same as the panel.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until, BASE } from '../lib.js';

/** The SS1 power analyzer: label on the panel, tag, decimals configured (none: the plant's 1). */
const ANALYZER = [
  ['Voltage L1', 'SS1.PA.V_L1', 1], ['Current L1', 'SS1.PA.I_L1', 1], ['Active power', 'SS1.PA.P_kW', 1],
  ['Reactive power', 'SS1.PA.Q_kvar', 1], ['Power factor', 'SS1.PA.PF', 2], ['Frequency', 'SS1.PA.Hz', 2],
  ['Energy', 'SS1.PA.kWh', 0],
];

/** The decimals of the first number in a shown value ("230.1 V" → 1), or null when none is shown. */
function decimalsShown(text) {
  const m = String(text).trim().match(/(-?\d+)(?:\.(\d+))?/);
  return m ? (m[2] || '').length : null;
}

test('the API gives each tag its decimals: its own, the plant\'s, none for an integer, null for a bool', async () => {
  const api = await adminApi();
  const tag = async (name) => requireOk(await api.call('GET', `/api/tags/${encodeURIComponent(name)}`), name);
  assert.equal((await tag('SS1.PA.Hz')).decimals, 2, 'its own');
  assert.equal((await tag('SS1.PA.kWh')).decimals, 0, 'its own, 0');
  assert.equal((await tag('SS1.PA.V_L1')).decimals, 1, 'the plant\'s [hmi] decimals');
  const counter = await tag('SS1.PA.Comm.Requests');
  assert.deepEqual([counter.kind, counter.decimals], ['int', 0], 'an integer: none');
  assert.equal((await tag('SS1.ELCB.Closed')).decimals, null, 'a bool: not a number');
  const session = requireOk(await api.call('GET', '/api/session'), 'session');
  assert.deepEqual(session.hmi, { decimals: 1, date_format: 'YYYY-MM-DD' });
});

test('one tag, one number of decimals: the panel, the main screen and the tag browser', async () => {
  const c = credentials().operator;
  const b = await launch('19-decimals');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    // The panel's power analyzer: every quantity with its configured count.
    await page.goto(`${BASE}/#/ss1`);
    const rows = page.locator('section:has(#pa-ss1) tbody tr');
    await rows.first().waitFor();
    const value = (label) => rows.filter({ has: page.locator('td', { hasText: new RegExp(`^${label}$`) }) }).locator('.value');
    await until('the analyzer shows numbers', async () => {
      for (const [label] of ANALYZER) if (!/^-?\d/.test((await value(label).textContent()).trim())) return false;
      return true;
    }, 15_000);
    const panel = {};
    for (const [label] of ANALYZER) panel[label] = (await value(label).textContent()).trim();
    for (const [label, , want] of ANALYZER) {
      assert.equal(decimalsShown(panel[label]), want, `${label}: "${panel[label]}" has ${want} decimals`);
    }
    await b.screenshot('panel');

    // The main screen's diagram: the analyzer read-outs (V, I, P) with one decimal.
    await page.goto(`${BASE}/#/main`);
    const readouts = page.locator('section[data-panel="ss1"] text.sl-value');
    // "V L1 230.1 V": the label, the number, the units ("V L1 ?" until a value comes).
    const number = (text) => (text.trim().match(/ (-?\d+(?:\.\d+)?) \S+$/) || [])[1];
    await until('the diagram shows numbers', async () => {
      const t = await readouts.allTextContents();
      return t.length >= 7 && t.every((x) => number(x) !== undefined);
    }, 15_000);
    for (const text of await readouts.allTextContents()) {
      assert.equal(decimalsShown(number(text)), 1, `the diagram's "${text}" has one decimal`);
    }

    // The tag browser, list and details, as on the panel.
    await page.goto(`${BASE}/#/tags`);
    for (const [, tag, want] of [ANALYZER[1], ANALYZER[5], ANALYZER[6]]) {
      await page.locator('#tag-search').fill(tag);
      const row = page.locator(`#tag-list .vlist-row[data-tag="${tag}"]`);
      await row.waitFor({ timeout: 10_000 });
      await until(`${tag} in the list`, async () => decimalsShown(await row.locator('.value').textContent()) !== null, 10_000);
      await row.click();
      await until(`${tag} in the details`, async () => decimalsShown(await page.locator('#tag-value').textContent()) !== null, 10_000);
      const list = (await row.locator('.value').textContent()).trim();
      const details = (await page.locator('#tag-value').textContent()).trim();
      assert.equal(decimalsShown(list), want, `${tag} in the list: "${list}"`);
      assert.equal(decimalsShown(details), want, `${tag} in the details: "${details}"`);
    }
    await b.screenshot('tag-browser');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});

test('the microgrid overview: one decimal for V, I and P whatever their size, two for the frequency', async () => {
  const c = credentials().operator;
  const b = await launch('19-decimals-microgrid');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/microgrid`);
    const cells = page.locator('#mg-units-table tbody tr td.num > .value');
    await until('the units table shows numbers', async () => {
      const t = await cells.allTextContents();
      return t.length >= 6 && t.filter((x) => /\d/.test(x)).length >= 6;
    }, 15_000);
    const texts = (await cells.allTextContents()).map((t) => t.trim()).filter((t) => /^-?\d/.test(t));
    const counts = new Set(texts.map(decimalsShown));
    assert.deepEqual([...counts], [1], `every V, I, P, SoC and setpoint with one decimal: ${texts.join(' | ')}`);
    const hz = page.locator('#mg-demand').locator('xpath=..').locator('dt', { hasText: 'Frequency' }).locator('xpath=following-sibling::dd[1]');
    await until('the frequency', async () => decimalsShown(await hz.textContent()) !== null, 10_000);
    assert.equal(decimalsShown(await hz.textContent()), 2, `frequency "${await hz.textContent()}"`);
    await b.screenshot('microgrid');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
