// 13. A trainer runs a fault drill from the Simulation panel: injects a
// permanent zone fault, watches the fault-isolation sequence isolate it on
// the panel screen, then repairs it. The trainer is an Operator whose group
// was given the `simulation` screen; every action is a `training` event.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, toolbar, adminApi, requireOk, until, BASE } from '../lib.js';
import { restorePanel } from '../fixtures.js';

const PANEL = 'ss1';
const ZONE = 2;
const TRAINER = { user: 'e2e-trainer', password: 'trainer-password-e2e-1' };

async function ensureTrainer(api) {
  requireOk(await api.call('PUT', '/api/groups/trainers/screens', { screens: ['main', PANEL, 'events', 'simulation'] }), 'giving the trainers group the Simulation screen');
  const r = await api.call('POST', '/api/users', { name: TRAINER.user, role: 'operator', group: 'trainers', password: TRAINER.password });
  if (r.status !== 201 && r.status !== 409) requireOk(r, 'creating the trainer');
}

test('a trainer injects a zone fault from the Simulation panel; the sequence isolates it; the trainer repairs it', async () => {
  const api = await adminApi();
  await restorePanel(api, PANEL);
  await ensureTrainer(api);
  const b = await launch('13-simulation-panel');
  const page = b.page;
  const breaker = (name) => page.locator(`tr[data-breaker-row="${name}"] .bk-text`);
  const faultCell = page.locator(`#sim-faults-table tr[data-panel="${PANEL}"][data-zone="${ZONE}"] .sim-fault`);
  try {
    await login(page, TRAINER.user, TRAINER.password);
    assert.ok((await toolbar(page)).includes('simulation'), 'the trainer has the Simulation screen');
    await page.goto(`${BASE}/#/simulation`);
    await page.locator('#sim-faults-table').waitFor();
    // Panels by the plant's names (their screens' labels), not their ids (issue 33, finding 11).
    const { screens } = (await api.call('GET', '/api/screens')).body;
    const name = screens.find((e) => e.kind === 'panel' && (e.panel || e.id) === PANEL).label;
    assert.notEqual(name, PANEL, 'the demo panel has a name apart from its id');
    await page.locator(`#sim-faults-table tr[data-panel="${PANEL}"] th`, { hasText: name }).first().waitFor({ timeout: 10_000 });
    assert.equal(await page.locator(`#sim-fault-panel option[value="${PANEL}"]`).textContent(), name, 'the panel picker names the panel');
    await b.screenshot('panel');

    await page.locator('#sim-fault-panel').selectOption(PANEL);
    await page.locator('#sim-fault-zone').selectOption(String(ZONE));
    await page.locator('#sim-fault-kind').selectOption('permanent');
    await page.locator('#sim-inject').click();
    await faultCell.filter({ hasText: 'PERMANENT' }).waitFor({ timeout: 10_000 });
    await b.screenshot('fault-injected');

    // The panel screen: the sequence finds the faulty zone and leaves it isolated.
    await page.goto(`${BASE}/#/${PANEL}`);
    await page.locator(`#${PANEL}-faulty`, { hasText: `Zone ${ZONE}` }).waitFor({ timeout: 60_000 });
    await page.locator(`#${PANEL}-step`, { hasText: 'isolated' }).waitFor({ timeout: 30_000 });
    await b.screenshot('isolated');
    assert.match(await breaker(`zone${ZONE}`).textContent(), /OPEN|TRIPPED/);
    for (const other of [1, 2, 3, 4].filter((z) => z !== ZONE)) {
      assert.equal(await breaker(`zone${other}`).textContent(), 'CLOSED', `zone ${other} restored`);
    }
    assert.equal(await breaker('elcb').textContent(), 'CLOSED');

    // Repair from the Simulation panel.
    await page.goto(`${BASE}/#/simulation`);
    await page.locator(`#sim-repair-${PANEL}-${ZONE}`).click();
    await faultCell.filter({ hasText: 'none' }).waitFor({ timeout: 10_000 });
    await b.screenshot('repaired');

    // Both actions are training events with the trainer's name.
    const log = await until('the training events', async () => {
      const r = await api.call('GET', '/api/events?type=training&limit=50');
      const mine = (r.body?.events || []).filter((e) => e.user === TRAINER.user);
      return mine.length >= 2 ? mine : false;
    });
    assert.ok(log.some((e) => /injected a permanent fault on zone 2/.test(e.message)), JSON.stringify(log));
    assert.ok(log.some((e) => /repaired zone 2/.test(e.message)), JSON.stringify(log));
    assert.ok(log.every((e) => e.message.startsWith('Training:')), JSON.stringify(log));
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await restorePanel(api, PANEL).catch(() => {});
  }
});

test('a transient fault set to clear before the reclose: the panel restores every zone, nothing isolated', async () => {
  const api = await adminApi();
  await restorePanel(api, PANEL);
  await ensureTrainer(api);
  const b = await launch('13-simulation-transient');
  const page = b.page;
  const breaker = (name) => page.locator(`tr[data-breaker-row="${name}"] .bk-text`);
  try {
    await login(page, TRAINER.user, TRAINER.password);
    await page.goto(`${BASE}/#/simulation`);
    await page.locator('#sim-faults-table').waitFor();
    await page.locator('#sim-fault-panel').selectOption(PANEL);
    await page.locator('#sim-fault-zone').selectOption(String(ZONE));
    await page.locator('#sim-fault-kind').selectOption('transient');
    // Shorter than the panel's reclose delay: the first reclose holds.
    await page.locator('#sim-fault-clears').fill('1');
    await page.locator('#sim-inject').click();
    await page.goto(`${BASE}/#/${PANEL}`);
    await page.locator(`#${PANEL}-last`, { hasText: /every zone restored.*, 1 trips/ }).waitFor({ timeout: 60_000 });
    await b.screenshot('restored');
    assert.equal(await page.locator(`#${PANEL}-faulty`).textContent(), 'none');
    for (const z of [1, 2, 3, 4]) assert.equal(await breaker(`zone${z}`).textContent(), 'CLOSED', `zone ${z} closed`);
    assert.equal(await breaker('elcb').textContent(), 'CLOSED');
    const log = requireOk(await api.call('GET', '/api/events?type=training&limit=50'), 'events').events;
    assert.ok(log.some((e) => e.user === TRAINER.user && /transient fault \(clears after 1 s\)/.test(e.message)), JSON.stringify(log));
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await restorePanel(api, PANEL).catch(() => {});
  }
});
