// Shared helpers of the browser tests: launching Debian's Chromium through
// playwright-core, logging in, calling the API, and saving screenshots.

import { chromium } from 'playwright-core';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
export const BASE = process.env.GRIDSCADA_URL || 'http://127.0.0.1:18181';
export const ARTIFACTS = process.env.GRIDSCADA_ARTIFACTS || path.resolve(here, '../artifacts');
const CREDENTIALS = process.env.GRIDSCADA_CREDENTIALS;

/** {administrator: {user, password}, ...} from the demo's credentials.txt ("ROLE USERNAME PASSWORD" lines). */
export function credentials() {
  if (!CREDENTIALS) throw new Error('GRIDSCADA_CREDENTIALS is not set (path of the demo credentials.txt)');
  const out = {};
  for (const line of fs.readFileSync(CREDENTIALS, 'utf8').split('\n')) {
    const [role, user, password] = line.trim().split(/\s+/);
    if (role && user && password) out[role] = { user, password };
  }
  return out;
}

/**
 * Launches headless Chromium with a fresh profile; returns {browser, context, page, close}.
 * `locale` (e.g. 'en-US') sets the browser's language and formats.
 */
export async function launch(name, { locale } = {}) {
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'gridscada-chromium-'));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    headless: true,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync'],
    viewport: { width: 1366, height: 768 },
    acceptDownloads: true,
    ...(locale ? { locale } : {}),
  });
  const page = context.pages()[0] || await context.newPage();
  const problems = [];
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  page.on('console', (m) => {
    // CSP violations and script errors are test failures: the HMI must run under default-src 'self'.
    if (m.type() === 'error' && !/Failed to load resource/.test(m.text())) problems.push(`console: ${m.text()}`);
  });
  let shot = 0;
  return {
    context,
    page,
    problems,
    /** Saves a PNG of the page as ARTIFACTS/NAME-NN-label.png. */
    async screenshot(label) {
      fs.mkdirSync(ARTIFACTS, { recursive: true });
      shot += 1;
      const file = path.join(ARTIFACTS, `${name}-${String(shot).padStart(2, '0')}-${label}.png`);
      await page.screenshot({ path: file });
      return file;
    },
    async close() {
      await context.close();
      fs.rmSync(profile, { recursive: true, force: true });
    },
  };
}

/** Logs in through the login form and waits for the toolbar. */
export async function login(page, user, password) {
  await page.goto(`${BASE}/`);
  await page.locator('#login-user').fill(user);
  await page.locator('#login-password').fill(password);
  await page.locator('#login-submit').click();
  await page.locator('#current-user', { hasText: user }).waitFor();
  await page.locator('#toolbar a').first().waitFor();
}

/** The screens in the toolbar, by id. */
export async function toolbar(page) {
  return page.locator('#toolbar a').evaluateAll((as) => as.map((a) => a.dataset.screen));
}

/** An API session outside the browser (for setup: users, faults). */
export class Api {
  constructor() { this.cookie = ''; }

  async login(user, password) {
    const r = await this.call('POST', '/api/session', { username: user, password });
    return r;
  }

  async call(method, p, body) {
    const headers = { Accept: 'application/json' };
    if (this.cookie) headers.Cookie = this.cookie;
    // As a browser does: a logged-in change names its origin (the server refuses it otherwise).
    // A browser's Origin: scheme, host and port, never the sub-path.
    if (this.cookie && method !== 'GET' && method !== 'HEAD') headers.Origin = new URL(BASE).origin;
    if (body !== undefined) headers['Content-Type'] = 'application/json';
    const resp = await fetch(`${BASE}${p}`, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
    const set = resp.headers.get('set-cookie');
    if (set) this.cookie = set.split(';')[0];
    const text = await resp.text();
    let json = null;
    try { json = text ? JSON.parse(text) : null; } catch { json = null; }
    return { status: resp.status, body: json, text };
  }
}

/** An admin API session. */
export async function adminApi() {
  const c = credentials().administrator;
  const api = new Api();
  const r = await api.login(c.user, c.password);
  if (r.status !== 200) throw new Error(`admin login failed: ${r.status} ${r.text}`);
  return api;
}

/** Throws a readable error when an API call that the test depends on is not wired yet. */
export function requireOk(r, what) {
  if (r.status >= 200 && r.status < 300) return r.body;
  const detail = r.body && (r.body.detail || r.body.error);
  throw new Error(`${what}: HTTP ${r.status}${detail ? ` (${detail})` : ''}`);
}

/** Polls f until it returns a truthy value. */
export async function until(what, f, timeoutMs = 20_000, stepMs = 250) {
  const end = Date.now() + timeoutMs;
  let last;
  while (Date.now() < end) {
    last = await f();
    if (last) return last;
    await new Promise((r) => setTimeout(r, stepMs));
  }
  throw new Error(`timed out after ${timeoutMs} ms waiting for ${what}`);
}

/** axe-core's source, run in the page through the debugger protocol (the page's CSP allows no injected script tag). */
let axeSource = null;
function axe() {
  if (!axeSource) axeSource = fs.readFileSync(path.join(here, 'node_modules/axe-core/axe.min.js'), 'utf8');
  return axeSource;
}

/**
 * Runs axe-core (WCAG 2.x A and AA, and best practice) on the page as it is;
 * returns the violations as [{id, impact, help, nodes: [target...]}].
 */
export async function runAxe(page) {
  if (!(await page.evaluate(() => typeof window.axe === 'object'))) await page.evaluate(axe());
  return page.evaluate(async () => {
    const r = await window.axe.run(document, { resultTypes: ['violations'] });
    return r.violations.map((v) => ({ id: v.id, impact: v.impact, help: v.help,
      nodes: v.nodes.map((n) => `${n.target.join(' ')}${n.any[0] && n.any[0].message ? `: ${n.any[0].message}` : ''}`) }));
  });
}

/** The serious and critical findings of runAxe. */
export const seriousFindings = (violations) => violations.filter((v) => v.impact === 'serious' || v.impact === 'critical');

/** Waits until a screen has drawn: no "Loading…" left. */
export async function settled(page) {
  await page.waitForFunction(() => !document.querySelector('#screen .loading') && document.querySelector('#screen').children.length > 0, null, { timeout: 15_000 });
}

/** A computed colour "rgb(r, g, b)" → [r, g, b]; transparent (and none) → null. */
export const rgb = (c) => { const m = /rgba?\((\d+), (\d+), (\d+)(?:, ([\d.]+))?\)/.exec(c || ''); return m && (m[4] === undefined || Number(m[4]) > 0) ? m.slice(1, 4).map(Number) : null; };
/** A saturated red: red well above green and blue. Takes a computed colour or [r, g, b]. */
export const isRed = (c) => { const v = Array.isArray(c) ? c : rgb(c); return !!v && v[0] > 120 && v[0] - v[1] > 70 && v[0] - v[2] > 70; };
