// Switching on the network screen (the demo plant's 11 kV ring: two
// normally-open points, feeding the two LV panels and the microgrid). Select-before-operate from the HMI: the preview names the
// customers who lose supply, and the downstream sections turn grey as the
// feeder breaker's status changes; a selection reserves the device (another
// operator is refused and sees who holds it) and times out; a cable taken
// out for work (opened both ends, earthed) cannot be closed onto, a
// "Do not close" tag refuses the close from the HMI and the API alike, and
// every step is in the event log.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, requireOk, until, runAxe, seriousFindings, BASE } from '../lib.js';
import { apiAs, state, operateApi, ensure } from './net.js';

async function openNetwork(role, name) {
  const c = credentials()[role];
  const b = await launch(name);
  await b.page.setViewportSize({ width: 1600, height: 1000 });
  await login(b.page, c.user, c.password);
  await b.page.goto(`${BASE}/#/network`);
  await b.page.locator('.net-section[data-section="c1"][data-state]').waitFor();
  return b;
}

/** Clicks a device and selects `operation` in its dialog. */
async function select(page, device, operation) {
  await page.locator(`.net-switch[data-device="${device}"]`).click();
  await page.locator('dialog select[name="op"]').selectOption(operation);
  await page.locator('dialog button[type="submit"]').click();
  await page.locator('dialog .net-countdown').waitFor();
}

test('opening the feeder breaker by select-before-operate: the preview names the customers, the sections go grey with the status', async () => {
  const api = await apiAs('supervisor');
  await ensure(api, 'f1', 'CLOSED');
  // Every device read at least once (just after start some are not yet):
  // the preview's figures are then those the screen will show.
  // Every customer on supply too (an earlier test may have left a panel's
  // zone to be restored): the preview counts those F1 would take off.
  await until('no section of unknown state, every customer on supply', async () => {
    const u = await state(api, 'NET.CustomersUnknown');
    const off = await state(api, 'NET.CustomersOff');
    return u && u.value === 0 && off && off.value === 0 && (await state(api, 'NET.Sec.c1.State')).value === 'ENERGISED';
  }, 60_000);
  const expected = requireOk(await api.call('GET', '/api/network/preview?device=f1&operation=open'), 'preview');
  assert.ok(expected.customers_lose > 0, 'opening F1 takes customers off supply');
  const b = await openNetwork('operator', 'net1');
  try {
    // The screen shows UNKNOWN until the first live values arrive.
    await b.page.locator('.net-section[data-section="c1"][data-state="ENERGISED"]').waitFor({ timeout: 10_000 });
    assert.deepEqual(seriousFindings(await runAxe(b.page)), [], 'axe on the network screen');
    // When each downstream section turns DEAD on the screen, by the browser's clock.
    await b.page.evaluate((ids) => {
      window.__deadAt = {};
      for (const id of ids) {
        const el = document.querySelector(`.net-section[data-section="${id}"]`);
        new MutationObserver(() => {
          if (el.dataset.state === 'DEAD' && !window.__deadAt[id]) window.__deadAt[id] = Date.now();
        }).observe(el, { attributes: true, attributeFilter: ['data-state'] });
      }
    }, expected.lose_supply);
    await select(b.page, 'f1', 'open');
    const dialog = b.page.locator('dialog');
    await assert.doesNotReject(dialog.locator('.net-preview', { hasText: `(${expected.customers_lose} customers)` }).waitFor({ timeout: 3000 }));
    for (const s of expected.lose_supply.slice(0, 3)) assert.match(await dialog.locator('.net-preview').innerText(), new RegExp(`\\b${s}\\b`));
    await b.screenshot('select-preview');
    await dialog.locator('button[type="submit"]', { hasText: 'Execute' }).click();
    await b.page.locator('.net-section[data-section="c1"][data-state="DEAD"]').waitFor({ timeout: 10_000 });
    await until('every section of the preview dead on the screen', () => b.page.evaluate((ids) => ids.every((id) => window.__deadAt[id]), expected.lose_supply), 5000);
    // The status change, as the server saw it (the poll that read the breaker open).
    const status = await state(api, 'MV.F1.CB.Closed');
    assert.equal(status.value, false);
    const deadAt = await b.page.evaluate(() => Math.max(...Object.values(window.__deadAt)));
    const latency = deadAt - status.timestamp;
    console.log(`feeder breaker status change -> last downstream section grey on the screen: ${latency} ms`);
    assert.ok(latency < 250, `the sections turned grey ${latency} ms after the status change (limit 250 ms)`);
    // Grey: the dead section's bar is not the energised colour.
    const fill = await b.page.locator('.net-section[data-section="c1"] .net-sec').evaluate((e) => getComputedStyle(e).fill);
    const energisedFill = await b.page.locator('.net-section[data-section="ps_bb"] .net-sec').evaluate((e) => getComputedStyle(e).fill);
    assert.notEqual(fill, energisedFill);
    assert.match(await b.page.locator('#net-CustomersOff').innerText(), new RegExp(`^${expected.customers_lose}$`));
    await b.screenshot('f1-open');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await ensure(api, 'f1', 'CLOSED');
  }
  const events = requireOk(await api.call('GET', '/api/events?limit=50'), 'events').events.map((e) => `${e.kind} ${e.message}`).join('\n');
  assert.match(events, /switching_selected .*Feeder 1 breaker/);
  assert.match(events, /switching_executed .*open Feeder 1 breaker .*executed/);
});

test('a selection reserves the device: another operator is refused and sees who holds it; it times out', async () => {
  const sup = await apiAs('supervisor');
  const op = credentials().operator.user;
  await ensure(sup, 'rmu1_s2', 'CLOSED');
  const a = await openNetwork('operator', 'net2a');
  const b = await openNetwork('supervisor', 'net2b');
  try {
    await select(a.page, 'rmu1_s2', 'open');
    const r = await sup.call('POST', '/api/switching/selections', { device: 'rmu1_s2', operation: 'open' });
    assert.equal(r.status, 409);
    assert.equal(r.body.error, 'reserved');
    assert.match(r.body.detail, new RegExp(op));
    // Any other door is refused too while the selection stands.
    const w = await sup.call('POST', '/api/tags/MV.RMU1.S2.Cmd/write', { value: false });
    assert.equal(w.status, 409);
    assert.equal(w.body.error, 'reserved');
    await b.page.locator(`.net-switch[data-device="rmu1_s2"][data-held-by="${op}"]`).waitFor({ timeout: 5000 });
    await b.screenshot('held-by-other');
    // The selection lapses after the plant's select timeout: the server
    // executes it no more, and the HMI sends nothing.
    const { timeout_s: timeoutS, selections } = requireOk(await sup.call('GET', '/api/switching/selections'), 'selections');
    const held = selections.find((x) => x.device === 'rmu1_s2');
    await a.page.locator('dialog .net-countdown', { hasText: 'timed out' }).waitFor({ timeout: (timeoutS + 5) * 1000 });
    const late = await (await apiAs('operator')).call('POST', `/api/switching/selections/${held.id}/execute`);
    assert.equal(late.status, 404);
    assert.match(late.body.detail, /timed out/);
    await a.page.locator('dialog button[type="submit"]').click();
    await a.page.locator('.toast-error', { hasText: 'timed out' }).waitFor({ timeout: 5000 });
    assert.equal((await state(sup, 'NET.Sw.rmu1_s2.Position')).value, 'CLOSED', 'nothing operated');
    assert.deepEqual(requireOk(await sup.call('GET', '/api/switching/selections'), 'selections').selections, []);
    await b.page.locator('.net-switch[data-device="rmu1_s2"][data-held-by=""]').waitFor({ timeout: 5000 });
    assert.deepEqual(a.problems, []);
    assert.deepEqual(b.problems, []);
  } finally {
    await a.close();
    await b.close();
  }
});

test('a cable out for work: earthed, tagged "Do not close", and no door closes onto it', async () => {
  const api = await apiAs('operator');
  const sup = await apiAs('supervisor');
  // Take cable C2 out: open both ends, earth it.
  await ensure(api, 'rmu1_s2', 'CLOSED');
  await ensure(api, 'rmu2_s1', 'CLOSED');
  await ensure(api, 'rmu1_e2', 'OPEN');
  const b = await openNetwork('operator', 'net3');
  try {
    for (const [device, operation] of [['rmu1_s2', 'open'], ['rmu2_s1', 'open']]) {
      await select(b.page, device, operation);
      await b.page.locator('dialog button[type="submit"]', { hasText: 'Execute' }).click();
      await b.page.locator(`.net-switch[data-device="${device}"][data-position="OPEN"]`).waitFor({ timeout: 10_000 });
    }
    await b.page.locator('.net-section[data-section="c2"][data-state="DEAD"]').waitFor();
    // Earthing the dead cable is allowed.
    await select(b.page, 'rmu1_e2', 'close');
    assert.equal(await b.page.locator('dialog .net-refusals').count(), 0);
    await b.page.locator('dialog button[type="submit"]', { hasText: 'Execute' }).click();
    await b.page.locator('.net-section[data-section="c2"][data-state="EARTHED"]').waitFor({ timeout: 10_000 });
    // A "Do not close" tag on the ring switch, from the HMI.
    await b.page.locator('.net-switch[data-device="rmu1_s2"]').click();
    await b.page.locator('dialog input[name="tag"]').check();
    await b.page.locator('dialog button[type="submit"]').click();
    await b.page.locator('dialog select[name="kind"]').selectOption('do_not_close');
    await b.page.locator('dialog input[name="reason"]').fill('cable C2 out for jointing');
    await b.page.locator('dialog input[name="work_ref"]').fill('WO-2026-118');
    await b.page.locator('dialog button[type="submit"]').click();
    await b.page.locator('.net-switch[data-device="rmu1_s2"][data-tag="DO NOT CLOSE"]').waitFor({ timeout: 5000 });
    await b.page.locator('table.net-tags td', { hasText: 'cable C2 out for jointing' }).waitFor();
    // The HMI shows both refusals before anything is sent, and the close is refused.
    await select(b.page, 'rmu1_s2', 'close');
    const refusals = b.page.locator('dialog .net-refusals');
    await refusals.locator('li[data-rule="safety_tag"]').waitFor();
    await refusals.locator('li[data-rule="closing_onto_earthed"]').waitFor();
    await b.screenshot('refused-preview');
    await b.page.locator('dialog button[type="submit"]').click();
    await b.page.locator('.toast-error', { hasText: 'DO NOT CLOSE' }).waitFor({ timeout: 5000 });
    assert.equal((await state(api, 'NET.Sw.rmu1_s2.Position')).value, 'OPEN');
    // The API, by a plain write and by select-before-operate: refused, the rule named.
    const w = await sup.call('POST', '/api/tags/MV.RMU1.S2.Cmd/write', { value: true });
    assert.equal(w.status, 409);
    assert.equal(w.body.error, 'safety_tag');
    const viaSbo = await operateApi(sup, 'rmu1_s2', 'close');
    assert.equal(viaSbo.status, 409);
    assert.equal(viaSbo.body.error, 'safety_tag');
    // The tag removed (with a reason) from the tag list: closing onto the
    // earthed cable is still refused, by its own rule.
    await b.page.locator('table.net-tags button', { hasText: 'Remove' }).click();
    await b.page.locator('dialog input[name="reason"]').fill('jointing done');
    await b.page.locator('dialog button[type="submit"]').click();
    await b.page.locator('.net-switch[data-device="rmu1_s2"][data-tag=""]').waitFor({ timeout: 5000 });
    const onto = await operateApi(api, 'rmu1_s2', 'close');
    assert.equal(onto.status, 409);
    assert.equal(onto.body.error, 'closing_onto_earthed');
    // Restore: remove the earth, close both ends.
    await ensure(api, 'rmu1_e2', 'OPEN');
    await ensure(api, 'rmu2_s1', 'CLOSED');
    await ensure(api, 'rmu1_s2', 'CLOSED');
    await b.page.locator('.net-section[data-section="c2"][data-state="ENERGISED"]').waitFor({ timeout: 10_000 });
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
  const events = requireOk(await sup.call('GET', '/api/events?limit=200'), 'events').events.map((e) => `${e.kind} ${e.message}`).join('\n');
  assert.match(events, /safety_tag_placed .*DO NOT CLOSE placed on .*WO-2026-118/);
  assert.match(events, /safety_tag_removed .*jointing done/);
  assert.match(events, /write_refused .*safety tag DO NOT CLOSE/);
  assert.match(events, /switching_executed .*close RMU1 earth switch, cable C2/);
});

test('a switching programme takes cable C2 out for work and restores it, step by step, every step in the event log', async () => {
  const sup = await apiAs('supervisor');
  for (const [d, p] of [['rmu1_s2', 'CLOSED'], ['rmu2_s1', 'CLOSED'], ['rmu2_s2', 'OPEN'], ['rmu1_e2', 'OPEN'], ['rmu2_e2', 'OPEN']]) await ensure(sup, d, p);
  // Bad input: nothing is stored, every problem named with its step.
  const before = requireOk(await sup.call('GET', '/api/switching/programmes'), 'programmes').programmes.length;
  const bad = await sup.call('POST', '/api/switching/programmes', { name: 'bad', steps: [{ kind: 'operate', device: 'nope', operation: 'open' }, { kind: 'remove_tag', device: 'f1', tag_kind: 'maybe' }] });
  assert.equal(bad.status, 400);
  assert.match(bad.body.detail, /step 1: no switching device 'nope'/);
  assert.match(bad.body.detail, /step 2: tag kind 'maybe'/);
  assert.equal(requireOk(await sup.call('GET', '/api/switching/programmes'), 'programmes').programmes.length, before);
  const op = (device, operation) => ({ kind: 'operate', device, operation });
  const tag = (device) => ({ kind: 'place_tag', device, tag_kind: 'do_not_close', reason: 'C2 out for jointing', work_ref: 'WO-77' });
  const untag = (device) => ({ kind: 'remove_tag', device, tag_kind: 'do_not_close' });
  const steps = [
    op('rmu2_s2', 'close'), op('rmu1_s2', 'open'), op('rmu2_s1', 'open'), tag('rmu1_s2'), tag('rmu2_s1'),
    op('rmu1_e2', 'close'), op('rmu2_e2', 'close'), { kind: 'manual', text: 'jointing done, permit cancelled' },
    op('rmu1_e2', 'open'), op('rmu2_e2', 'open'), untag('rmu1_s2'), untag('rmu2_s1'),
    op('rmu2_s1', 'close'), op('rmu1_s2', 'close'), op('rmu2_s2', 'open'),
  ];
  // An impossible order is shown refused at its step, and cannot be approved.
  const wrong = requireOk(await sup.call('POST', '/api/switching/programmes', { name: 'C2 earthed first', steps: [op('rmu1_e2', 'close'), op('rmu1_s2', 'open')] }), 'wrong programme');
  assert.equal(wrong.steps[0].check.refusals[0].rule, 'earthing_energised');
  const refused = await sup.call('POST', `/api/switching/programmes/${wrong.id}/approve`);
  assert.equal(refused.status, 409);
  assert.equal(refused.body.error, 'earthing_energised');
  const prog = requireOk(await sup.call('POST', '/api/switching/programmes', { name: 'C2 out for jointing', steps }), 'programme');
  assert.ok(prog.steps.every((st) => st.check && st.check.refusals.length === 0), 'no step refused');
  // The supervisor approves it on the network screen.
  const s = await openNetwork('supervisor', 'net4s');
  try {
    await s.page.locator(`#net-programmes tr[data-programme="${prog.id}"] button`).click();
    await s.page.locator('#net-prog-approve').click();
    await s.page.locator('#net-prog-state[data-state="approved"]').waitFor();
    assert.deepEqual(s.problems, []);
  } finally {
    await s.close();
  }
  // The operator takes every step.
  const b = await openNetwork('operator', 'net4o');
  try {
    await b.page.locator(`#net-programmes tr[data-programme="${prog.id}"] button`).click();
    for (let n = 1; n <= steps.length; n++) {
      await b.page.locator('#net-prog-step', { hasText: `Do step ${n}` }).click();
      if (steps[n - 1].kind === 'operate') {
        await b.page.locator('dialog .net-countdown').waitFor();
        await b.page.locator('dialog button[type="submit"]', { hasText: 'Execute' }).click();
      } else {
        await b.page.locator('dialog button[type="submit"]').click();
      }
      await b.page.locator(`.net-step[data-step="${n}"].net-step-done`).waitFor({ timeout: 15_000 });
      if (n === 7) {
        await b.page.locator('.net-section[data-section="c2"][data-state="EARTHED"]').waitFor({ timeout: 10_000 });
        assert.equal(await b.page.locator('.net-switch[data-device="rmu1_s2"]').getAttribute('data-tag'), 'DO NOT CLOSE');
        await b.screenshot('programme-c2-earthed');
      }
    }
    await b.page.locator('#net-prog-state[data-state="completed"]').waitFor();
    await b.page.locator('.net-section[data-section="c2"][data-state="ENERGISED"]').waitFor({ timeout: 10_000 });
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
  const events = requireOk(await sup.call('GET', '/api/events?limit=400'), 'events').events.map((e) => `${e.kind} ${e.message}`).join('\n');
  for (let n = 1; n <= steps.length; n++) assert.match(events, new RegExp(`programme_step switching programme ${prog.id} 'C2 out for jointing' step ${n} of ${steps.length} done`));
  assert.match(events, new RegExp(`programme_approved switching programme ${prog.id}`));
  assert.match(events, new RegExp(`programme_completed switching programme ${prog.id}`));
});
