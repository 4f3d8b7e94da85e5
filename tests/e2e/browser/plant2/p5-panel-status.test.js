// What the operator must see of a panel's sequence (issue 15 #5, #10, #11,
// #12), on any plant: "Last sequence" says nothing happened yet instead of
// "restored in 0.0 s"; manual mode shows on the panel's diagram and on Main;
// a zone isolated as faulty reads FAULTY – ISOLATED on both; and Reset names
// the isolated zones and wants the repair confirmed before it re-energises.
// The header names a panel in manual mode too.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until, BASE } from '../lib.js';
import { restorePanel } from '../fixtures.js';

test('panel status: last sequence, manual mode, faulty zones, and the Reset dialog', async () => {
  const api = await adminApi();
  const { panels } = requireOk(await api.call('GET', '/api/panels'), 'panels');
  // The last panel whose zone loads have a voltage signal (the re-energised load is checked on the diagram).
  let p;
  for (const cand of [...panels].reverse()) {
    const prefix = cand.prefix || cand.id.toUpperCase();
    if ((await api.call('GET', `/api/tags/${prefix}.Zone${Math.min(2, cand.zones)}.Energised`)).status === 200) { p = cand; break; }
  }
  assert.ok(p, 'a panel with Energised signals on its zone loads');
  const id = p.id;
  const zone = Math.min(2, p.zones);
  await restorePanel(api, id, p.zones);
  const c = credentials().supervisor;
  const b = await launch('p5-panel-status');
  const page = b.page;
  const load = (scope) => page.locator(`${scope} .sl-load[data-zone="${zone}"]`);
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/${id}`);
    const last = page.locator(`#${id}-last`);
    await until('the last sequence is shown', async () => (await last.textContent()) !== '');
    assert.doesNotMatch(await last.textContent(), /0\.0 s/, 'no "restored in 0.0 s" when nothing was restored');

    // Manual mode, on the diagram and on Main.
    requireOk(await api.call('POST', `/api/panels/${id}/mode`, { mode: 'manual' }), 'manual mode');
    await page.locator('.panel-left .sl-manual[visibility="visible"]').waitFor({ timeout: 5000 });
    await page.locator('#mode-light', { hasText: `MANUAL: ${p.name}` }).waitFor({ timeout: 8000 });
    await b.screenshot('manual');
    await page.goto(`${BASE}/#/main`);
    await page.locator(`[data-mode-of="${id}"]:not([hidden])`).waitFor({ timeout: 5000 });
    await page.locator(`[data-panel="${id}"] .sl-manual[visibility="visible"]`).waitFor();
    for (const other of panels.filter((x) => x.id !== id)) {
      assert.equal(await page.locator(`[data-mode-of="${other.id}"]`).isHidden(), true, `${other.id} is in auto`);
    }
    requireOk(await api.call('POST', `/api/panels/${id}/mode`, { mode: 'auto' }), 'auto mode');
    await page.locator(`[data-mode-of="${id}"]`).waitFor({ state: 'hidden', timeout: 5000 });
    await page.locator('#mode-light').waitFor({ state: 'hidden', timeout: 8000 });

    // A permanent fault: the sequence isolates the zone; the diagrams say so.
    requireOk(await api.call('POST', '/api/sim/faults', { panel: id, zone, kind: 'permanent' }), 'fault');
    await page.locator(`[data-panel="${id}"] .sl-load[data-zone="${zone}"].io-faulty`).waitFor({ timeout: 60_000 });
    assert.equal(await load(`[data-panel="${id}"]`).locator('.sl-state').textContent(), 'FAULTY – ISOLATED');
    await b.screenshot('main-faulty');
    await page.goto(`${BASE}/#/${id}`);
    await page.locator(`#${id}-faulty`, { hasText: `Zone ${zone}` }).waitFor();
    await load('.panel-left').and(page.locator('.io-faulty')).waitFor();
    assert.equal(await load('.panel-left').locator('.sl-state').textContent(), 'FAULTY – ISOLATED');
    await until('the last sequence is told in words', async () => /isolated/.test(await last.textContent()));

    // Reset names the zone and will not go without the repair confirmed.
    await page.locator(`#${id}-reset`).click();
    await page.locator(`#${id}-reset-zones`, { hasText: `Zone ${zone}` }).waitFor();
    await b.screenshot('reset-dialog');
    await page.locator('dialog button[type="submit"]').click();
    assert.equal(await page.locator('dialog').count(), 1, 'not reset without the repair confirmed');
    await page.locator('dialog button', { hasText: 'Cancel' }).click();
    await page.locator('dialog').waitFor({ state: 'detached' });
    assert.match(await page.locator(`#${id}-faulty`).textContent(), new RegExp(`Zone ${zone}`), 'still isolated after Cancel');

    // Repaired: Reset with the repair confirmed re-energises it.
    requireOk(await api.call('DELETE', `/api/sim/faults/${id}/${zone}`), 'repair');
    await page.locator(`#${id}-reset`).click();
    await page.locator(`#${id}-reset-repaired`).check();
    await page.locator('dialog button[type="submit"]').click();
    await page.locator(`#${id}-faulty`, { hasText: 'none' }).waitFor({ timeout: 30_000 });
    await load('.panel-left').and(page.locator('.io-true')).waitFor({ timeout: 30_000 });
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await restorePanel(api, id, p.zones).catch(() => {});
  }
});
