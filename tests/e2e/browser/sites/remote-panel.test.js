// One remote site's panel on the central server: the central gridscada (a
// Sparkplug B host) holds the tags of a gridscada edge site under the site's
// prefix. An administrator draws the site's panel on a screen of the central
// server from those remote tags (its breakers and analyzer values), through
// the screen API as the editor saves it; an operator opens it and sees the
// edge's values live, and Bad quality as soon as the site's I/O device stops
// answering (the edge's DDEATH), then Good again when it answers (its DBIRTH).
//
// Run by tests/e2e/sparkplug_sites.py with GRIDSCADA_URL and
// GRIDSCADA_CREDENTIALS (the central server), GRIDSCADA_SITE (the edge node
// id, the prefix of its tags at the centre), GRIDSCADA_SITE_URL and
// GRIDSCADA_SITE_CREDENTIALS (the edge's own server, to read its values and
// to take its simulated device off line).
import test from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import { launch, login, adminApi, credentials, requireOk, until } from '../lib.js';

const SITE = process.env.GRIDSCADA_SITE;
const SITE_URL = process.env.GRIDSCADA_SITE_URL;
const SITE_CREDENTIALS = process.env.GRIDSCADA_SITE_CREDENTIALS;

/** A logged-in API session on the edge's own server. */
async function siteApi() {
  let cookie = '';
  const call = async (method, p, body) => {
    const headers = { Accept: 'application/json' };
    if (cookie) headers.Cookie = cookie;
    if (cookie && method !== 'GET') headers.Origin = new URL(SITE_URL).origin;
    if (body !== undefined) headers['Content-Type'] = 'application/json';
    const resp = await fetch(`${SITE_URL}${p}`, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
    const set = resp.headers.get('set-cookie');
    if (set) cookie = set.split(';')[0];
    const text = await resp.text();
    let json = null;
    try { json = text ? JSON.parse(text) : null; } catch { json = null; }
    return { status: resp.status, body: json, text };
  };
  const admin = fs.readFileSync(SITE_CREDENTIALS, 'utf8').split('\n')
    .map((l) => l.trim().split(/\s+/)).find(([role]) => role === 'administrator');
  requireOk(await call('POST', '/api/session', { username: admin[1], password: admin[2] }), 'login at the edge');
  return call;
}

test(`the panel of remote site ${SITE} on the central server follows the edge`, async () => {
  assert.ok(SITE && SITE_URL && SITE_CREDENTIALS, 'GRIDSCADA_SITE, GRIDSCADA_SITE_URL and GRIDSCADA_SITE_CREDENTIALS are set');
  const site = await siteApi();
  const central = await adminApi();

  // The site's first panel, as the edge configures it.
  const panels = requireOk(await site('GET', '/api/panels'), 'the edge\'s panels').panels;
  const panel = panels[0];
  const prefix = panel.prefix || String(panel.id).toUpperCase();
  const edgeTags = new Map(requireOk(await site('GET', '/api/tags'), 'the edge\'s tags').tags.map((t) => [t.name, t]));
  const breakers = [...edgeTags.keys()]
    .filter((n) => n.startsWith(`${prefix}.`) && n.endsWith('.Closed') && edgeTags.get(n).kind === 'bool')
    .sort();
  const values = ['PA.V_L1', 'PA.I_L1', 'PA.Hz'].map((v) => `${prefix}.${v}`).filter((n) => edgeTags.has(n));
  assert.ok(breakers.length >= 3, `the panel has breakers: ${breakers}`);
  assert.ok(values.length >= 1, `the panel has an analyzer: ${values}`);
  // The I/O device that reads the breakers.
  const io = edgeTags.get(breakers[0]).source.device;

  // Drawn at the centre from the remote tags SITE.TAG.
  const id = `${SITE}-${String(panel.id).toLowerCase()}`.replace(/[^a-z0-9_-]/g, '-');
  const elements = [{ type: 'text', text: `${SITE} – ${panel.name || prefix}`, x: 20, y: 10, w: 600, h: 30 }];
  breakers.forEach((b, i) => elements.push({ type: 'breaker', tag: `${SITE}.${b}`, label: b.slice(prefix.length + 1), x: 20 + 150 * i, y: 60, w: 140, h: 60 }));
  values.forEach((v, i) => elements.push({ type: 'value', tag: `${SITE}.${v}`, label: v.slice(prefix.length + 1), digits: 1, x: 20 + 200 * i, y: 160, w: 190, h: 50 }));
  await central.call('DELETE', `/api/screens/${id}`);
  requireOk(await central.call('PUT', `/api/screens/${id}`, { id, name: `${SITE} ${panel.name || prefix}`, width: 1200, height: 300, elements }), 'saving the screen at the centre');

  const b = await launch('remote-panel');
  const { page } = b;
  try {
    const op = credentials().operator;
    await login(page, op.user, op.password);
    await page.goto(`${new URL(page.url()).origin}/#/custom:${id}`);
    const shown = (tag) => page.locator(`.el-breaker[title^="${tag.slice(prefix.length + 1)}:"] .bk-text`);
    const valueOf = (i) => page.locator(`.el-value .el-value-text`).nth(i);

    // Live values: each breaker as the edge reads it, each value a number.
    await until('every breaker at the centre as the edge reads it', async () => {
      const now = new Map(requireOk(await site('GET', '/api/tags'), 'edge tags').tags.map((t) => [t.name, t]));
      for (const name of breakers) {
        const want = now.get(name).value ? 'CLOSED' : 'OPEN';
        if ((await shown(name).textContent()) !== want) return false;
      }
      return true;
    }, 30_000, 500);
    await until('the analyzer values shown Good', async () => {
      for (let i = 0; i < values.length; i++) {
        const t = await valueOf(i).textContent();
        if (!/^-?\d/.test(t) || !(await valueOf(i).getAttribute('class')).includes('q-good')) return false;
      }
      return true;
    }, 30_000, 500);
    await b.screenshot('live');

    // The site's I/O device stops answering: Bad at the edge, DDEATH, Bad here.
    requireOk(await site('POST', `/api/sim/devices/${encodeURIComponent(io)}/offline`, {}), 'device offline at the edge');
    await until(`${io}'s breakers UNKNOWN at the centre`, async () => {
      for (const name of breakers.filter((n) => edgeTags.get(n).source?.device === io)) {
        if ((await shown(name).textContent()) !== '? UNKNOWN') return false;
      }
      return true;
    }, 30_000, 250);
    const title = await page.locator(`.el-breaker[title^="${breakers[0].slice(prefix.length + 1)}:"]`).getAttribute('title');
    assert.match(title, /offline|Bad|quality/i, `the reason is shown: ${title}`);
    await b.screenshot('device-offline');

    // It answers again: the edge's rebirth of the device brings them back.
    requireOk(await site('POST', `/api/sim/devices/${encodeURIComponent(io)}/online`, {}), 'device online at the edge');
    await until(`${io}'s breakers known again at the centre`, async () => {
      for (const name of breakers) {
        if (!['CLOSED', 'OPEN'].includes(await shown(name).textContent())) return false;
      }
      return true;
    }, 60_000, 500);
    await b.screenshot('device-back');
    assert.deepEqual(b.problems, []);
  } finally {
    await b.close();
    await central.call('DELETE', `/api/screens/${id}`);
  }
});
