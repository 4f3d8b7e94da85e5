// Red and the alarm colours are for alarms (ISA-101; issue 33, finding 9):
// the "Inject fault" button and every other button with consequences, the
// session-expiry banner, the trend pens and the state text of an
// acknowledged alarm are drawn in neither red nor an alarm priority's
// colour, in the light and the dark theme. A trip and an unacknowledged
// alarm stay red (checked in 10-isa101-theme and here).
import test from 'node:test';
import assert from 'node:assert/strict';
import { launch, login, credentials, BASE, rgb, isRed } from '../lib.js';

const hex = (c) => [1, 3, 5].map((i) => parseInt(c.slice(i, i + 2), 16));
const distance = (a, b) => Math.hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]);

/** The page's alarm colours: red and the four priorities' colours. */
async function alarmColours(page) {
  return page.evaluate(() => {
    const css = getComputedStyle(document.documentElement);
    return ['--bad', '--bad-text', '--p-urgent', '--p-high', '--p-medium', '--p-low'].map((v) => [v, css.getPropertyValue(v).trim()]);
  });
}

/** Why colour `c` ("rgb(...)" or "#rrggbb") reads as an alarm colour, or null. */
function alarmLike(c, alarms) {
  const v = c.startsWith('#') ? hex(c) : rgb(c);
  if (!v) return null;
  if (isRed(v)) return 'red';
  for (const [name, a] of alarms) {
    if (a && distance(v, hex(a)) < 60) return `close to ${name} ${a}`;
  }
  return null;
}

/** The colours to check, as drawn now. */
async function drawn(page) {
  return page.evaluate(async () => {
    const style = (el) => getComputedStyle(el);
    const out = {};
    // A button with consequences, as every dialog and screen draws it.
    const button = document.createElement('button');
    button.className = 'btn btn-danger';
    button.textContent = 'Open breaker';
    document.body.append(button);
    out['button with consequences: background'] = style(button).backgroundColor;
    out['button with consequences: text'] = style(button).color;
    out['button with consequences: border'] = style(button).borderTopColor;
    button.remove();
    // The session-expiry banner, shown as it would be.
    const banner = document.getElementById('session-warning');
    const wasHidden = banner.hidden;
    banner.hidden = false;
    out['session banner: background'] = style(banner).backgroundColor;
    out['session banner: text'] = style(banner).color;
    banner.hidden = wasHidden;
    // The trend pens.
    const { PEN_COLORS } = await import('/js/components/chart.js');
    PEN_COLORS.forEach((c, i) => { out[`trend pen ${i + 1}`] = c; });
    // An acknowledged, active alarm and an unacknowledged one, as the tables draw them.
    const { drawAlarmRows } = await import('/js/components/alarmtable.js');
    const table = document.createElement('table');
    const body = document.createElement('tbody');
    table.append(body);
    document.body.append(table);
    const alarm = (id, state, acked) => ({ id, state, acked, active: true, priority: 500, kind: 'hi', selection: 'test', message: 'test alarm', activated_at: Date.now(), value: 1 });
    drawAlarmRows(body, [alarm(1, 'ack_active', true), alarm(2, 'unack_active', false)]);
    const stateOf = (id) => style(body.querySelector(`tr[data-alarm-id="${id}"] .alarm-state`)).color;
    out['"ACTIVE, acked" state text'] = stateOf(1);
    const unacked = stateOf(2);
    table.remove();
    return { out, unacked };
  });
}

test('red and the alarm colours are kept for alarms: buttons, the session banner, trend pens, acked alarms', async () => {
  const c = credentials().supervisor;
  const b = await launch('14-red-for-alarms-only');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/main`);
    await page.locator('#toolbar a').first().waitFor();
    for (const theme of ['light', 'dark']) {
      await page.evaluate((t) => { if (t === 'dark') document.documentElement.dataset.theme = 'dark'; else delete document.documentElement.dataset.theme; }, theme);
      const alarms = await alarmColours(page);
      const { out, unacked } = await drawn(page);
      const wrong = Object.entries(out).map(([what, colour]) => [what, colour, alarmLike(colour, alarms)]).filter(([, , why]) => why);
      assert.deepEqual(wrong, [], `${theme}: drawn in an alarm colour (what, colour, why): ${JSON.stringify(wrong)}`);
      // An unacknowledged active alarm is an alarm: still red.
      assert.ok(isRed(rgb(unacked)), `${theme}: an unacknowledged active alarm's state is red: ${unacked}`);
      // The pens stay apart from each other and from the plot's background.
      const pens = Object.entries(out).filter(([k]) => k.startsWith('trend pen')).map(([, v]) => hex(v));
      for (let i = 0; i < pens.length; i += 1) {
        for (let j = i + 1; j < pens.length; j += 1) assert.ok(distance(pens[i], pens[j]) > 40, `${theme}: pens ${i + 1} and ${j + 1} are told apart`);
      }
    }
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});

test('the Simulation panel\'s "Inject fault" is not red', async () => {
  const c = credentials().administrator;
  const b = await launch('14-inject-fault');
  const page = b.page;
  try {
    await login(page, c.user, c.password);
    await page.goto(`${BASE}/#/simulation`);
    const inject = page.locator('#sim-inject');
    await inject.waitFor();
    const alarms = await alarmColours(page);
    const colours = await inject.evaluate((e) => { const s = getComputedStyle(e); return [s.backgroundColor, s.color, s.borderTopColor]; });
    const wrong = colours.filter((x) => alarmLike(x, alarms));
    assert.deepEqual(wrong, [], `"Inject fault" is drawn in an alarm colour: ${colours}`);
    await b.screenshot('inject-fault');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
  }
});
