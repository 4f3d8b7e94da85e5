// The sequence step pushed live (issue 15 #9): during a fault the panel
// screen shows every step the sequence takes, from the derived tags
// {prefix}.Seq.*, in plain words with the codes in a tooltip.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, BASE } from '../lib.js';
import { restorePanel } from '../fixtures.js';

test('the sequence step is pushed live, in plain words', async () => {
  const api = await adminApi();
  const { panels } = requireOk(await api.call('GET', '/api/panels'), 'panels');
  const p = panels[1] || panels[0];
  const id = p.id;
  await restorePanel(api, id, p.zones);
  const c = credentials().operator;
  const b = await launch('p5b-sequence');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/${id}`);
    const step = page.locator(`#${id}-step`);
    await step.filter({ hasText: 'Idle: watching for a trip' }).waitFor();
    assert.match(await step.getAttribute('title'), /^step idle, count_L_cur_c \d+, count_L_cur_sv \d+$/, 'the codes in a tooltip');
    // Record every step shown, as it is drawn.
    await page.evaluate((sel) => {
      window.seenSteps = [];
      const el = document.querySelector(sel);
      new MutationObserver(() => {
        const last = window.seenSteps[window.seenSteps.length - 1];
        if (!last || last.text !== el.textContent) window.seenSteps.push({ code: el.dataset.step, text: el.textContent });
      }).observe(el, { childList: true, characterData: true, subtree: true, attributes: true });
    }, `#${id}-step`);
    requireOk(await api.call('POST', '/api/sim/faults', { panel: id, zone: 1, kind: 'permanent' }), 'fault');
    await step.filter({ hasText: 'isolated' }).waitFor({ timeout: 60_000 });
    const seen = await page.evaluate(() => window.seenSteps);
    const codes = [...new Set(seen.map((s) => s.code))];
    for (const want of ['tripped', 'oluc', 'oldc', 'isolated']) assert.ok(codes.includes(want), `step ${want} seen: ${codes}`);
    assert.ok(seen.some((s) => /^Testing zone \d+: /.test(s.text)), `a zone test in words: ${seen.map((s) => s.text).join(' | ')}`);
    assert.ok(seen.length >= 8, `every step seen (${seen.length})`);
    await b.screenshot('isolated');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await restorePanel(api, id, p.zones).catch(() => {});
  }
});
