// The axe-core run over every screen the toolbar offers, in the light and the
// dark theme (issue 15 #16): zero serious or critical findings.

import fs from 'node:fs';
import path from 'node:path';
import { ARTIFACTS, BASE, runAxe, settled, toolbar } from './lib.js';

/** Sets the theme with the header's toggle (as an operator does). */
export async function setTheme(page, dark) {
  const btn = page.locator('#theme-toggle');
  if ((await btn.getAttribute('aria-pressed')) !== String(dark)) await btn.click();
  await page.waitForFunction((d) => (document.documentElement.dataset.theme === 'dark') === d, dark);
}

/** A screen has drawn and its first requests are answered. */
async function ready(page, id) {
  await settled(page).catch(() => {});
  await page.waitForLoadState('networkidle', { timeout: 5000 }).catch(() => {});
  if (id === 'trends') await page.locator('#trend-status', { hasText: /samples|No data|Cannot/ }).waitFor({ timeout: 15_000 }).catch(() => {});
  if (id.startsWith('custom:')) await page.locator('#custom-screen .el').first().waitFor({ timeout: 15_000 }).catch(() => {});
}

/**
 * Opens every screen in `screens` in the light and then the dark theme, and
 * calls `visit(id, theme)` once each has drawn.
 */
export async function visitScreens(page, screens, visit) {
  for (const theme of ['light', 'dark']) {
    await setTheme(page, theme === 'dark');
    for (const id of screens) {
      await page.goto(`${BASE}/#/${id}`);
      // The screen's link is marked (inside its group's closed list, so attached, not visible).
      await page.locator(`#toolbar a[data-screen="${id}"][aria-current="page"]`).waitFor({ state: 'attached' });
      await ready(page, id);
      await visit(id, theme);
    }
  }
}

/**
 * Runs axe on every screen of the toolbar (and the alarm history, and the
 * footer's summary per area), in both themes. Returns {findings: [{screen,
 * theme, id, impact, nodes}], screens: [ids], counts: {impact: nodes}} and
 * writes it to ARTIFACTS/axe-NAME.json.
 */
export async function axeEveryScreen(page, name, shot) {
  const screens = await toolbar(page);
  const findings = [];
  const counts = {};
  const record = (screen, theme, violations) => {
    for (const v of violations) {
      counts[v.impact] = (counts[v.impact] || 0) + v.nodes.length;
      findings.push({ screen, theme, ...v });
    }
  };
  // The footer at its smallest: its list scrolls, and must be reachable from the keyboard.
  await page.locator('#footer-resize').focus();
  await page.keyboard.press('End');
  await page.waitForFunction(() => { const l = document.querySelector('#alarm-footer .footer-list:not([hidden])'); return l && l.scrollHeight > l.clientHeight; });
  record('footer-scrolling', 'light', await runAxe(page));
  for (let i = 0; i < 4; i++) await page.keyboard.press('ArrowUp');
  await visitScreens(page, screens, async (id, theme) => {
    record(id, theme, await runAxe(page));
    if (id === 'alarms') {
      await page.locator('#alarms-tab-history').click();
      await page.locator('#alarms-history, #screen .error').first().waitFor({ timeout: 15_000 });
      record('alarms/history', theme, await runAxe(page));
    }
    if (id === screens[0]) {
      // The footer's summary per area, then back to rows.
      await page.locator('#footer-view').click();
      await page.locator('#footer-summary-table').waitFor();
      record(`${id}+footer-summary`, theme, await runAxe(page));
      if (shot) await shot(`${theme}-footer-summary`);
      await page.locator('#footer-view').click();
      await page.locator('#footer-alarms').waitFor();
    }
    if (shot && (['main', 'trends', 'alarms'].includes(id) || id.startsWith('custom:p4b-elements'))) await shot(`${theme}-${id.replace(':', '-')}`);
  });
  await setTheme(page, false);
  const report = { screens, counts, findings };
  fs.mkdirSync(ARTIFACTS, { recursive: true });
  fs.writeFileSync(path.join(ARTIFACTS, `axe-${name}.json`), JSON.stringify(report, null, 1));
  return report;
}

/** The serious and critical findings, one line each, for an assertion message. */
export function describe(findings) {
  return findings.filter((f) => f.impact === 'serious' || f.impact === 'critical')
    .map((f) => `${f.screen} (${f.theme}) ${f.impact} ${f.id}: ${f.nodes.slice(0, 3).join(' | ')}`);
}
