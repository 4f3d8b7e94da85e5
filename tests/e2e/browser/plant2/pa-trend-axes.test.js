// Trends (issue 15 #15): one Y axis per unit, each pen on the axis of its
// units; pan and zoom back in time with buttons, a drag and the mouse wheel,
// the window never reaching into the future; Live as before; the table and
// the CSV follow the window. Tag names come from this plant's API.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, until, BASE } from '../lib.js';

test('trend: an axis per unit; pan and zoom back in time, never into the future', async () => {
  const api = await adminApi();
  const { tags } = requireOk(await api.call('GET', '/api/tags?search=.PA.&limit=200'), 'tags');
  const byUnit = (u) => tags.filter((t) => t.units === u).map((t) => t.name);
  const [v1, v2] = byUnit('V');
  const a1 = byUnit('A')[0];
  const p1 = byUnit('kW')[0];
  assert.ok(v1 && v2 && a1 && p1, 'the plant has V, A and kW tags');
  const pens = [v1, v2, a1, p1];
  const unitOf = new Map(tags.map((t) => [t.name, t.units]));
  const c = credentials().operator;
  const b = await launch('pa-trend-axes');
  const page = b.page;
  const view = async () => page.locator('#trend-canvas').evaluate((e) => ({ from: Number(e.dataset.from), to: Number(e.dataset.to) }));
  const duration = async () => Number(await page.locator('#trend-duration').inputValue()) * 1000;
  /** Does `f` and waits until the loaded window changed. */
  const moved = async (what, f) => {
    const before = await view();
    await f();
    await page.waitForFunction((t) => Number(document.getElementById('trend-canvas').dataset.to) !== t, before.to, { timeout: 10_000 })
      .catch(() => { throw new Error(`${what}: the window did not move`); });
    await page.locator('#trend-status', { hasText: 'samples' }).waitFor();
    const after = await view();
    assert.ok(after.to <= Date.now(), `${what}: the window ends in the past (${new Date(after.to).toISOString()})`);
    return { before, after };
  };
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/trends?pens=${pens.join(',')}`);
    for (const p of pens) await page.locator(`#trend-pens li[data-pen="${p}"]`).waitFor();
    await page.locator('#trend-status', { hasText: '(live)' }).waitFor({ timeout: 15_000 });

    // Live off: one window, whose axes we check against its data.
    await page.locator('#trend-live').uncheck();
    await until('the frozen window loaded', async () => !/live|Loading/.test(await page.locator('#trend-status').textContent()));
    const axes = await page.locator('#trend-axes li').evaluateAll((ls) => ls.map((l) => ({ unit: l.dataset.unit, side: l.dataset.side, min: Number(l.dataset.min), max: Number(l.dataset.max), pens: l.dataset.pens.split(',') })));
    assert.deepEqual(axes.map((a) => a.unit), ['V', 'A', 'kW'], 'one axis per unit, in the order of the pens');
    assert.deepEqual(axes.map((a) => a.side), ['left', 'right', 'left'], 'alternating sides');
    for (const p of pens) {
      const on = axes.filter((a) => a.pens.includes(p));
      assert.equal(on.length, 1, `${p} is on one axis`);
      assert.equal(on[0].unit, unitOf.get(p), `${p} is on the axis of its units`);
    }
    // Each axis spans its own pens' data, and only theirs.
    const { from, to } = await view();
    const data = requireOk(await api.call('GET', `/api/trends?tags=${pens.join(',')}&from=${from}&to=${to}&points=200`), 'trend data');
    const span = (names) => {
      let lo = Infinity; let hi = -Infinity;
      for (const s of data.series.filter((x) => names.includes(x.tag))) for (const k of s.buckets) if (k.count) { lo = Math.min(lo, k.min); hi = Math.max(hi, k.max); }
      return { lo, hi };
    };
    for (const a of axes) {
      const d = span(a.pens);
      if (!Number.isFinite(d.lo)) continue;
      assert.ok(a.min <= d.lo && a.max >= d.hi, `the ${a.unit} axis ${a.min}..${a.max} holds its data ${d.lo}..${d.hi}`);
    }
    const vAxis = axes.find((a) => a.unit === 'V');
    const aAxis = axes.find((a) => a.unit === 'A');
    assert.ok(vAxis.min !== aAxis.min || vAxis.max !== aAxis.max, 'V and A are not on one shared scale');
    await b.screenshot('axes');

    // Back: half a window into the past.
    const dur = await duration();
    let m = await moved('Back', () => page.locator('#trend-back').click());
    assert.ok(Math.abs((m.before.to - m.after.to) - dur / 2) <= 2000, `back by half the window: ${m.before.to - m.after.to} ms of ${dur}`);
    assert.equal(await page.locator('#trend-live').isChecked(), false);

    // A drag to the right goes further back in time.
    const box = await page.locator('#trend-canvas').boundingBox();
    m = await moved('Drag', async () => {
      await page.mouse.move(box.x + box.width * 0.4, box.y + box.height / 2);
      await page.mouse.down();
      await page.mouse.move(box.x + box.width * 0.5, box.y + box.height / 2, { steps: 3 });
      await page.mouse.move(box.x + box.width * 0.6, box.y + box.height / 2, { steps: 3 });
      await page.mouse.up();
    });
    assert.ok(m.after.to < m.before.to - dur * 0.1, `dragged back: ${m.before.to - m.after.to} ms`);

    // The wheel zooms in around the pointer: a shorter window.
    m = await moved('Wheel', async () => {
      await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
      await page.mouse.wheel(0, -200);
    });
    const zoomed = await duration();
    assert.ok(zoomed < dur, `zoomed in: ${zoomed} < ${dur} ms`);
    assert.ok(Math.abs((m.after.to - m.after.from) - zoomed) <= 1000, 'the duration list says the window shown');
    await b.screenshot('panned-zoomed');

    // Zoom out: twice the window.
    await moved('Zoom out', () => page.locator('#trend-zoom-out').click());
    assert.ok(Math.abs(await duration() - 2 * zoomed) <= 2000, 'zoomed out twice');

    // Forward, again and again: the window comes up to now and never passes it.
    for (let i = 0; i < 8; i++) {
      const before = await view();
      await page.locator('#trend-forward').click();
      await page.waitForFunction((t) => Number(document.getElementById('trend-canvas').dataset.to) !== t, before.to, { timeout: 3000 }).catch(() => {});
      await page.locator('#trend-status', { hasText: 'samples' }).waitFor();
      const v = await view();
      assert.ok(v.to <= Date.now(), `forward ${i + 1}: ends at ${new Date(v.to).toISOString()}, not in the future`);
    }
    assert.ok((await view()).to >= Date.now() - 60_000, 'forward brings the window up to now');
    // The wheel at the right edge, zooming out, cannot reach past now either.
    await page.mouse.move(box.x + box.width - 20, box.y + box.height / 2);
    await page.mouse.wheel(0, 300);
    await page.waitForTimeout(400); // the chart asks once after a burst of wheel steps (150 ms)
    await page.locator('#trend-status', { hasText: 'samples' }).waitFor();
    assert.ok((await view()).to <= Date.now(), 'a zoom out never reaches into the future');

    // The table and the CSV follow the window.
    const { from: f2, to: t2 } = await view();
    assert.match(await page.locator('#trend-csv').getAttribute('href'), new RegExp(`from=${f2}&to=${t2}`));
    await page.locator('#trend-show-table').click();
    await page.locator('#trend-data-table tbody tr').first().waitFor();
    assert.match(await page.locator('#trend-data-table thead').textContent(), /\(A\)/);

    // Live as before: the window ends now and follows it.
    await page.locator('#trend-live').check();
    await page.locator('#trend-status', { hasText: '(live)' }).waitFor({ timeout: 10_000 });
    const lv = await view();
    assert.ok(Math.abs(lv.to - Date.now()) < 10_000, 'live ends now');
    // A zoom of the live window stays live, and still ends now.
    const d0 = await duration();
    await page.locator('#trend-zoom-in').click();
    await until('the live window zoomed in', async () => Math.abs((await duration()) - d0 / 2) <= 1000, 5000, 100);
    await until('the zoomed window loaded', async () => { const v = await view(); return Math.abs((v.to - v.from) - d0 / 2) <= 1000; }, 10_000, 100);
    assert.equal(await page.locator('#trend-live').isChecked(), true, 'still live after a zoom');
    await page.locator('#trend-status', { hasText: '(live)' }).waitFor();
    assert.ok(Math.abs((await view()).to - Date.now()) < 10_000, 'the zoomed live window ends now');
    await b.screenshot('live');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
