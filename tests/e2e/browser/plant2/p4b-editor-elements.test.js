// The screen builder's other elements and screen operations, on another
// plant: an administrator places a busbar, a rectangle, a bar with limits, a
// multi-state indicator with a label per value, a link to another screen and
// a panel's whole single-line diagram, binding tags by picking them; resizes
// an element by its grip and deletes one with the Delete key; saves, renames
// and copies the screen; exports the copy as JSON, deletes it, and imports the
// file back as a new screen. An operator then opens the screen and sees the
// state label of the live value, the bar filled to the value, the embedded
// panel's diagram with its zones, and follows the link.
import test from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { launch, login, toolbar, credentials, adminApi, requireOk, until, BASE, ARTIFACTS } from '../lib.js';

const ID = 'p4b-elements';
const COPY = `${ID}-copy`;
const NAME = 'Pump elements';
const RENAMED = 'Pump station elements';
const PANEL = 'pb'; // the workshop panel: 6 zones
const ZONES = 6;
const STATES = [[0, 'Stopped'], [1, 'Manual'], [2, 'Automatic']];

async function pick(page, search, tag) {
  await page.locator('#pick-search').fill(search);
  await page.locator(`.pick-tag[data-tag="${tag}"]`).click();
  await page.locator('#pick-search').waitFor({ state: 'detached' });
}

async function setField(page, id, value) {
  await page.locator(`#${id}`).fill(String(value));
  await page.locator(`#${id}`).press('Tab');
}

/** Places the selected (just added) element at x, y. */
async function moveTo(page, x, y) {
  await setField(page, 'prop-x', x);
  await setField(page, 'prop-y', y);
}

/** Adds an element from the palette and waits until it is drawn and selected. */
async function add(page, type, index) {
  await page.locator(`[data-palette="${type}"]`).click();
  await page.locator(`#editor-canvas .el-selected[data-element-index="${index}"][data-element-type="${type}"]`).waitFor();
}

/** Drags from the centre of `locator` by dx, dy with the mouse. */
async function dragBy(page, locator, dx, dy) {
  await locator.scrollIntoViewIfNeeded();
  const box = await locator.boundingBox();
  const x = box.x + box.width / 2;
  const y = box.y + box.height / 2;
  await page.mouse.move(x, y);
  await page.mouse.down();
  await page.mouse.move(x + dx, y + dy, { steps: 5 });
  await page.mouse.up();
}

async function save(page, version) {
  await page.locator('#editor-save').click();
  await page.locator('#editor-status', { hasText: `as version ${version}.` }).waitFor();
}

test('every other element type, resize, delete, rename, copy, export and import; an operator sees them live', async () => {
  const api = await adminApi();
  await api.call('DELETE', `/api/screens/${ID}`);
  await api.call('DELETE', `/api/screens/${COPY}`);
  // Known values for the operator's checks below (the admin may write both).
  requireOk(await api.call('POST', '/api/tags/RTU1.Mode/write', { value: 1 }), 'writing RTU1.Mode');
  requireOk(await api.call('POST', '/api/tags/RTU1.Setpoint/write', { value: 15 }), 'writing RTU1.Setpoint');
  const admin = credentials().administrator;
  let exported;
  const b = await launch('p4b-editor');
  const page = b.page;
  page.on('dialog', (d) => { b.problems.push(`a JavaScript dialog opened: ${d.message()}`); d.dismiss(); });
  try {
    await login(page, admin.user, admin.password);
    await page.goto(`${BASE}/#/editor`);
    await page.locator('#editor-new').click();
    await page.locator('#editor-new-id').fill(ID);
    await page.locator('#editor-new-name').fill(NAME);
    await page.locator('dialog button[type="submit"]').click();
    await page.locator('#editor-status', { hasText: `New screen "${NAME}"` }).waitFor();

    // 0: a busbar across the top.
    await add(page, 'line', 0);
    await page.locator('#editor-props input[type="checkbox"]').check();
    await setField(page, 'prop-w', 680);
    await moveTo(page, 20, 20);
    // 1: a label that is deleted below with the Delete key.
    await add(page, 'text', 1);
    await setField(page, 'prop-text', 'Scratch label');
    await moveTo(page, 760, 20);
    // 2: a rectangle, resized by its grip below.
    await add(page, 'rect', 2);
    await setField(page, 'prop-label', 'Pump house');
    await moveTo(page, 20, 50);
    // 3: a bar of the pump setpoint, 0 to 60 kW.
    await add(page, 'bar', 3);
    await page.locator('#prop-pick-tag').click();
    await pick(page, 'setpoint', 'RTU1.Setpoint');
    await page.locator('#prop-tag', { hasText: 'RTU1.Setpoint' }).waitFor();
    await setField(page, 'prop-label', 'Setpoint');
    await setField(page, 'prop-max', 60);
    await moveTo(page, 300, 50);
    // 4: a multi-state indicator of the pump mode, a label per value.
    await add(page, 'multistate', 4);
    await page.locator('#prop-pick-tag').click();
    await pick(page, 'Pump mode', 'RTU1.Mode');
    await page.locator('#prop-tag', { hasText: 'RTU1.Mode' }).waitFor();
    await setField(page, 'prop-label', 'Mode');
    await page.locator('#prop-states').fill(STATES.map(([v, l]) => `${v}=${l}`).join('\n'));
    await page.locator('#prop-states').press('Tab');
    await moveTo(page, 520, 50);
    // 5: a link to the copy made below.
    await add(page, 'link', 5);
    await setField(page, 'prop-screen', `custom:${COPY}`);
    await setField(page, 'prop-label', 'Open the copy');
    await moveTo(page, 720, 60);
    // 6: the workshop panel's single-line diagram, whole.
    await add(page, 'panel', 6);
    await page.locator('#prop-panel').selectOption(PANEL);
    await setField(page, 'prop-w', 720);
    await moveTo(page, 20, 210);
    await page.locator(`#editor-canvas [data-element-index="6"] svg.single-line[data-zones="${ZONES}"]`).waitFor();
    assert.equal(await page.locator('#editor-canvas [data-element-index]').count(), 7);

    // Resize the rectangle by its grip: +57, +33 px snaps to 260 x 150.
    await page.locator('#editor-canvas [data-element-index="2"] .el-cover').click();
    await until('the rectangle selected', async () => (await page.locator('#prop-label').inputValue()) === 'Pump house');
    await dragBy(page, page.locator('#editor-canvas [data-element-index="2"] .el-grip'), 57, 33);
    await until('the rectangle resized', async () => (await page.locator('#prop-w').inputValue()) === '260'
      && (await page.locator('#prop-h').inputValue()) === '150');
    // Select the scratch label and delete it with the Delete key.
    await page.locator('#editor-canvas [data-element-index="1"] .el-cover').click();
    await until('the label selected', async () => (await page.locator('#prop-text').count()) === 1);
    await page.keyboard.press('Delete');
    await until('the label deleted', async () => (await page.locator('#editor-canvas [data-element-index]').count()) === 6);
    assert.equal(await page.locator('#editor-canvas [data-element-type="text"]').count(), 0);
    await b.screenshot('drawn');

    await save(page, 1);
    const saved = requireOk(await api.call('GET', `/api/screens/${ID}`), 'saved screen');
    assert.equal(saved.version, 1);
    assert.equal(saved.name, NAME);
    assert.deepEqual(saved.elements.map((e) => e.type), ['line', 'rect', 'bar', 'multistate', 'link', 'panel']);
    const [line, rect, bar, multi, link, panel] = saved.elements;
    assert.deepEqual([line.busbar, line.x, line.y, line.w], [true, 20, 20, 680]);
    assert.deepEqual([rect.label, rect.x, rect.y, rect.w, rect.h], ['Pump house', 20, 50, 260, 150]);
    assert.deepEqual([bar.tag, bar.label, bar.min, bar.max], ['RTU1.Setpoint', 'Setpoint', 0, 60]);
    assert.deepEqual([multi.tag, multi.label], ['RTU1.Mode', 'Mode']);
    assert.deepEqual(multi.states, STATES.map(([value, label]) => ({ value, label })));
    assert.deepEqual([link.screen, link.label], [`custom:${COPY}`, 'Open the copy']);
    assert.deepEqual([panel.panel, panel.w, panel.y], [PANEL, 720, 210]);

    // Rename: the next save is version 2 under the new name, in the toolbar too.
    await page.locator('#editor-rename').click();
    await page.locator('dialog input[name="name"]').fill(RENAMED);
    await page.locator('dialog button[type="submit"]', { hasText: 'Rename' }).click();
    await save(page, 2);
    const renamed = requireOk(await api.call('GET', `/api/screens/${ID}`), 'renamed screen');
    assert.deepEqual([renamed.id, renamed.name, renamed.version], [ID, RENAMED, 2]);
    assert.deepEqual(renamed.elements, saved.elements);
    await page.locator(`#toolbar a[data-screen="custom:${ID}"]`, { hasText: RENAMED }).waitFor({ state: 'attached' });

    // Copy: a new screen (version 1) with the same elements; the original stays at version 2.
    await page.locator('#editor-copy').click();
    assert.equal(await page.locator('#editor-new-id').inputValue(), COPY);
    assert.equal(await page.locator('#editor-new-name').inputValue(), `${RENAMED} (copy)`);
    await page.locator('dialog button[type="submit"]').click();
    await page.locator('#editor-status', { hasText: 'Save to keep it' }).waitFor();
    await save(page, 1);
    const copy = requireOk(await api.call('GET', `/api/screens/${COPY}`), 'copied screen');
    assert.deepEqual([copy.id, copy.name, copy.version], [COPY, `${RENAMED} (copy)`, 1]);
    assert.deepEqual(copy.elements, saved.elements);
    assert.equal(requireOk(await api.call('GET', `/api/screens/${ID}`), 'original').version, 2);
    assert.equal(await page.locator('#editor-screens').inputValue(), COPY);

    // Export the copy as a JSON file.
    const [download] = await Promise.all([page.waitForEvent('download'), page.locator('#editor-export').click()]);
    assert.equal(download.suggestedFilename(), `${COPY}.json`);
    fs.mkdirSync(ARTIFACTS, { recursive: true });
    const file = path.join(ARTIFACTS, download.suggestedFilename());
    await download.saveAs(file);
    exported = JSON.parse(fs.readFileSync(file, 'utf8'));
    assert.deepEqual([exported.id, exported.name, exported.version], [COPY, `${RENAMED} (copy)`, 1]);
    assert.deepEqual(exported.elements, saved.elements);

    // Delete the copy, then import the file back: a new screen again, from version 1.
    await page.locator('#editor-delete').click();
    await page.locator('dialog button[type="submit"]', { hasText: 'Delete' }).click();
    await until('the copy deleted', async () => (await api.call('GET', `/api/screens/${COPY}`)).status === 404);
    await until('the copy left the screen list', async () => (await page.locator(`#editor-screens option[value="${COPY}"]`).count()) === 0);
    await page.locator('#editor-import-file').setInputFiles(file);
    await page.locator('#editor-status', { hasText: `Imported "${RENAMED} (copy)" from ${COPY}.json: Save to keep it.` }).waitFor();
    assert.equal(await page.locator('#editor-canvas [data-element-index]').count(), 6);
    await save(page, 1);
    const imported = requireOk(await api.call('GET', `/api/screens/${COPY}`), 'imported screen');
    assert.deepEqual([imported.id, imported.name, imported.version], [COPY, `${RENAMED} (copy)`, 1]);
    assert.deepEqual(imported.elements, exported.elements);
    await until('the toolbar lists both screens', async () => {
      const t = await toolbar(page);
      return t.includes(`custom:${ID}`) && t.includes(`custom:${COPY}`);
    });
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }

  // An operator opens the screen.
  const op = { user: 'e2e-operator-p4b', password: 'operator-password-e2e-4b' };
  const made = await api.call('POST', '/api/users', { name: op.user, role: 'operator', password: op.password });
  if (made.status === 409) requireOk(await api.call('POST', `/api/users/${op.user}/password`, { password: op.password }), 'operator password');
  else requireOk(made, 'creating the operator');
  const o = await launch('p4b-operator');
  const opage = o.page;
  try {
    await login(opage, op.user, op.password);
    await opage.goto(`${BASE}/#/custom:${ID}`);
    await opage.locator('h1.screen-title', { hasText: RENAMED }).waitFor();
    const screen = opage.locator('#custom-screen');
    // The multi-state indicator shows the label of the live value, and follows a change.
    const state = screen.locator('[data-element-type="multistate"] .el-state');
    await state.filter({ hasText: /^Manual$/ }).waitFor();
    assert.equal(await screen.locator('[data-element-type="multistate"] .el-label').textContent(), 'Mode');
    requireOk(await api.call('POST', '/api/tags/RTU1.Mode/write', { value: 2 }), 'writing RTU1.Mode');
    await state.filter({ hasText: /^Automatic$/ }).waitFor();
    assert.match(await state.getAttribute('class'), /q-good/);

    // The bar: 15 kW of 0 to 60 fills a quarter of the track; 45 kW three quarters.
    const track = screen.locator('[data-element-type="bar"] .el-bar-track');
    const fill = track.locator('.el-bar-fill');
    const fraction = async () => {
      const [t, f] = await Promise.all([track.boundingBox(), fill.boundingBox()]);
      return f.width / t.width;
    };
    await until('the bar at 15 kW', async () => (await track.getAttribute('aria-valuenow')) === '15');
    assert.ok(Math.abs((await fraction()) - 0.25) < 0.02, `bar filled ${await fraction()}, not 0.25`);
    assert.match(await screen.locator('[data-element-type="bar"] .value').textContent(), /15.*kW/);
    requireOk(await api.call('POST', '/api/tags/RTU1.Setpoint/write', { value: 45 }), 'writing RTU1.Setpoint');
    await until('the bar at 45 kW', async () => (await track.getAttribute('aria-valuenow')) === '45');
    assert.ok(Math.abs((await fraction()) - 0.75) < 0.02, `bar filled ${await fraction()}, not 0.75`);

    // The busbar and the rectangle are drawn as placed.
    // (A horizontal line has an empty bounding box: Playwright calls it hidden, so check how it is drawn.)
    const bus = screen.locator('[data-element-type="line"] svg line.sl-bus');
    await bus.waitFor({ state: 'attached' });
    assert.deepEqual(await bus.evaluate((l) => [l.getAttribute('x2'), l.getAttribute('y1'), getComputedStyle(l).strokeWidth]), ['680', '5', '6px']);
    const rbox = await screen.locator('[data-element-type="rect"]').boundingBox();
    assert.deepEqual([Math.round(rbox.width), Math.round(rbox.height)], [260, 150]);
    assert.equal(await screen.locator('[data-element-type="rect"] .el-rect-label').textContent(), 'Pump house');

    // The embedded panel: its single-line diagram with its six zones, live.
    const diagram = screen.locator(`[data-element-type="panel"] svg.single-line[data-zones="${ZONES}"]`);
    await diagram.waitFor();
    assert.equal(await diagram.locator('g.sl-load[data-zone]').count(), ZONES);
    assert.equal(await diagram.locator('g.sl-breaker[data-breaker^="zone"]').count(), ZONES);
    for (const z of [1, ZONES]) {
      await diagram.locator(`g.sl-breaker[data-breaker="zone${z}"] .sl-state`, { hasText: /^(CLOSED|OPEN|TRIPPED)$/ }).waitFor();
    }
    await diagram.locator('g.sl-breaker[data-breaker="elcb"] .sl-state', { hasText: /^(CLOSED|TRIPPED)$/ }).waitFor();
    const shot = await o.screenshot('operator-view');
    assert.ok(fs.statSync(shot).size > 10_000);

    // The link opens the other screen (the copy, imported back).
    await screen.locator('[data-element-type="link"] a.el-link', { hasText: 'Open the copy' }).click();
    await until('the link navigated', async () => (await opage.evaluate(() => location.hash)) === `#/custom:${COPY}`);
    await opage.locator('h1.screen-title', { hasText: `${RENAMED} (copy)` }).waitFor();
    await opage.locator('#custom-screen [data-element-type="multistate"] .el-state', { hasText: /^Automatic$/ }).waitFor();
    assert.deepEqual(o.problems, []);
  } finally {
    await o.close();
  }
});
