// States in words everywhere (docs/HMI_STYLE.md rule 3; issue 33, finding 5):
// the tag browser shows a tag with `states` in those words (CLOSED, not
// TRUE), in the list and the details; a device's comm-failure alarm shows
// its value as COMM LOST / CONNECTED, not FALSE / TRUE.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until, BASE } from '../lib.js';

const TAG = 'CSS1.MCCB.Closed'; // states = { false = "OPEN", true = "CLOSED" }
const DEVICE = 'MG.Load';

test('the tag browser shows a tag\'s values in its state words', async () => {
  const c = credentials().supervisor;
  const b = await launch('16-state-words-tags');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/tags`);
    await page.locator('#tag-search').fill(TAG);
    const row = page.locator(`#tag-list .vlist-row[data-tag="${TAG}"]`);
    await row.waitFor({ timeout: 10_000 });
    await until('the list shows the value in words', async () => /^(OPEN|CLOSED)$/.test((await row.locator('.value').textContent()).trim()), 10_000);
    await row.click();
    await until('the details show the value in words', async () => /^(OPEN|CLOSED)$/.test((await page.locator('#tag-value').textContent()).trim()), 10_000);
    const shown = `${await row.locator('.value').textContent()} / ${await page.locator('#tag-value').textContent()}`;
    assert.doesNotMatch(shown, /TRUE|FALSE/, `no TRUE/FALSE for a tag with states: ${shown}`);
    await b.screenshot('tag-in-words');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});

test('a comm-failure alarm shows the device\'s state in words', async () => {
  const api = await adminApi();
  const c = credentials().supervisor;
  const b = await launch('16-state-words-comm');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.locator('#footer-alarms').waitFor();
    requireOk(await api.call('POST', `/api/sim/devices/${encodeURIComponent(DEVICE)}/offline`), 'taking the device offline');
    const row = page.locator('#footer-alarms tr', { hasText: `Communication lost with ${DEVICE}` });
    await row.first().waitFor({ timeout: 30_000 });
    const now = (await row.first().locator('td.alarm-value .alarm-value-now').textContent()).trim();
    assert.equal(now, 'COMM LOST', `the value now in words: ${now}`);
    await b.screenshot('comm-alarm');
    requireOk(await api.call('POST', `/api/sim/devices/${encodeURIComponent(DEVICE)}/online`), 'bringing the device online');
    // Back online: the value now reads CONNECTED beside the value at activation, both in words.
    await until('the device answers again', async () => {
      const t = (await row.first().locator('td.alarm-value').textContent().catch(() => '')) || '';
      return /CONNECTED/.test(t);
    }, 30_000);
    const cell = (await row.first().locator('td.alarm-value').textContent()).trim();
    assert.doesNotMatch(cell, /TRUE|FALSE/, `no TRUE/FALSE in the comm alarm's value: ${cell}`);
    assert.deepEqual(b.problems, []);
  } finally {
    await api.call('POST', `/api/sim/devices/${encodeURIComponent(DEVICE)}/online`).catch(() => {});
    await b.close();
  }
});
