// Labels whole (issue 33, finding 4): a trend pen is named in full, its
// description and its tag, however long; a state chip (AUTO) is as wide as
// its word, not stretched across its column.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, adminApi, requireOk, BASE } from '../lib.js';

test('trend pens named in full; state chips as wide as their word', async () => {
  const api = await adminApi();
  const { tags } = requireOk(await api.call('GET', '/api/tags?limit=1000'), 'tags');
  // The numeric tag with the longest name and description: the hardest to show whole.
  const pen = tags.filter((t) => t.kind === 'float' && t.units)
    .sort((a, b) => (b.name.length + (b.description || '').length) - (a.name.length + (a.description || '').length))[0];
  const { panels } = requireOk(await api.call('GET', '/api/panels'), 'panels');
  const c = credentials().operator;
  const b = await launch('23-labels');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/trends?pens=${encodeURIComponent(pen.name)}`);
    const name = page.locator(`#trend-pens li[data-pen="${pen.name}"] .pen-name`);
    await name.waitFor();
    await b.screenshot('pen');
    const shown = await name.evaluate((e) => ({ text: e.textContent, cut: e.scrollWidth > e.clientWidth + 1 || [...e.querySelectorAll('*')].some((c) => c.scrollWidth > c.clientWidth + 1) }));
    assert.ok(shown.text.includes(pen.name), `the pen shows its whole tag name: "${shown.text}"`);
    if (pen.description) assert.ok(shown.text.includes(pen.description), `and its description: "${shown.text}"`);
    assert.equal(shown.cut, false, `nothing of "${shown.text}" is cut off`);

    await page.goto(`${BASE}/#/${panels[0].id}`);
    const mode = page.locator(`#${panels[0].id}-mode`);
    await mode.filter({ hasText: /AUTO|MANUAL/ }).waitFor();
    const widths = await mode.evaluate((e) => {
      const r = document.createRange();
      r.selectNodeContents(e);
      return { chip: e.getBoundingClientRect().width, text: r.getBoundingClientRect().width, column: e.parentElement.getBoundingClientRect().width };
    });
    assert.ok(widths.chip < widths.text + 40, `the mode chip is ${Math.round(widths.chip)} px wide for ${Math.round(widths.text)} px of text (its list ${Math.round(widths.column)} px)`);
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
