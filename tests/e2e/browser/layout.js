// The layout sweep (issue 33): every screen the toolbar offers, at 1366x768,
// 1920x1080 and a 390-px phone, in the light and the dark theme, with a
// screenshot of each for a reviewer's eye. Checked on each: the header is one
// row (two short rows on a phone), and the page itself never scrolls
// sideways (a wide table or diagram scrolls inside its own card).

import { setTheme, visitScreens } from './a11y.js';
import { toolbar } from './lib.js';

export const SIZES = [[1366, 768], [1920, 1080], [390, 844]];

/**
 * Visits every screen at every size and theme; `shot(label)` saves a
 * screenshot. Returns the problems found, as sentences naming the screen.
 */
export async function layoutEveryScreen(page, shot) {
  const screens = await toolbar(page);
  const problems = [];
  for (const [w, hgt] of SIZES) {
    await page.setViewportSize({ width: w, height: hgt });
    await visitScreens(page, screens, async (id, theme) => {
      const m = await page.evaluate(() => ({
        header: Math.round(document.getElementById('header').getBoundingClientRect().height),
        sideways: document.documentElement.scrollWidth - window.innerWidth,
      }));
      const phone = w < 700;
      if (m.header > (phone ? 80 : 52)) problems.push(`${id} at ${w}x${hgt} (${theme}): the header is ${m.header} px high`);
      if (m.sideways > 1) problems.push(`${id} at ${w}x${hgt} (${theme}): the page scrolls sideways by ${m.sideways} px`);
      await shot(`${w}-${theme}-${id.replace(':', '-')}`);
    });
  }
  await page.setViewportSize({ width: 1366, height: 768 });
  await setTheme(page, false);
  return { screens, problems };
}
