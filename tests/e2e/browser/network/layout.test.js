// The network screen's layout, adjusted in the screen editor (the demo
// plant's 11 kV ring): "From network…" starts a drawn screen with a line per
// section where the automatic layout puts it; saved as "network", a line
// moved there moves its section on the network screen (devices and wires
// follow); deleted, the automatic layout is back.
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, requireOk, until, BASE } from '../lib.js';
import { apiAs } from './net.js';

const barX = async (page, section) => {
  const bar = page.locator(`.net-section[data-section="${section}"] .net-sec`);
  await bar.waitFor();
  return Number(await bar.getAttribute('x'));
};

test('an administrator moves a section in the screen editor, and the network screen draws it there', async () => {
  const admin = await apiAs('administrator');
  // A layout left by an earlier run would not be the automatic one.
  await admin.call('DELETE', '/api/screens/network');
  const c = credentials().administrator;
  const b = await launch('net-layout');
  try {
    await b.page.setViewportSize({ width: 1600, height: 1000 });
    await login(b.page, c.user, c.password);
    await b.page.goto(`${BASE}/#/network`);
    const autoX = await barX(b.page, 'c2');

    await b.page.goto(`${BASE}/#/editor`);
    await b.page.locator('#editor-from-network').click();
    assert.equal(await b.page.locator('#editor-new-id').inputValue(), 'network');
    await b.page.locator('dialog button[type="submit"]').click();
    const model = requireOk(await admin.call('GET', '/api/network'), 'network model');
    assert.equal(model.layout, null, 'no layout is saved yet');
    await assert.doesNotReject(b.page.locator('#editor-canvas .el').nth(model.sections.length - 1).waitFor({ timeout: 5000 }));
    assert.equal(await b.page.locator('#editor-canvas .el').count(), model.sections.length, 'a line per section');
    // Cable C2's line, found by its tooltip, dragged 300 px to the right.
    const cover = b.page.locator('#editor-canvas .el[title^="Section c2:"] .el-cover');
    await cover.scrollIntoViewIfNeeded();
    const box = await cover.boundingBox();
    await b.page.mouse.move(box.x + 5, box.y + box.height / 2);
    await b.page.mouse.down();
    await b.page.mouse.move(box.x + 105, box.y + box.height / 2, { steps: 3 });
    await b.page.mouse.move(box.x + 305, box.y + box.height / 2, { steps: 5 });
    await b.page.mouse.up();
    // The canvas and the properties are drawn again after the move.
    let movedX = autoX;
    await until('the moved line in the properties', async () => {
      movedX = Number(await b.page.locator('#prop-x').inputValue());
      return movedX !== autoX;
    }, 5000).catch(() => {});
    assert.ok(Math.abs(movedX - (autoX + 300)) <= 10, `the line moved to x ${movedX} (from ${autoX})`);
    await b.page.locator('#editor-save').click();
    await b.page.locator('#editor-status', { hasText: 'as version 1' }).waitFor();

    const saved = requireOk(await admin.call('GET', '/api/network'), 'network model');
    assert.equal(saved.layout.screen, 'network');
    assert.equal(saved.layout.sections.c2.x, movedX);
    assert.equal(Object.keys(saved.layout.sections).length, model.sections.length);

    await b.page.goto(`${BASE}/#/network`);
    await b.page.reload();
    assert.equal(await barX(b.page, 'c2'), movedX, 'the network screen draws C2 where the editor put it');
    // The devices on C2 still sit on the diagram, and the other sections
    // stay where they were.
    assert.equal(await barX(b.page, 'c1'), saved.layout.sections.c1.x);
    await b.page.locator('.net-switch[data-device="rmu1_s2"]').waitFor();
    await b.screenshot('network-adjusted-layout');

    requireOk(await admin.call('DELETE', '/api/screens/network'), 'deleting the layout');
    await b.page.reload();
    assert.equal(await barX(b.page, 'c2'), autoX, 'the automatic layout is back');
    assert.deepEqual(b.problems, []);
  } finally {
    await admin.call('DELETE', '/api/screens/network');
    await b.close();
  }
});
