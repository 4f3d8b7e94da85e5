// The sites sharing this server's database (`GET /api/sites`): a "Site"
// choice for the history screens, shown only when there is more than one.
// Another site's history is read as that site's servers record it
// (`site=` on the history endpoints), read-only.

import { get } from './api.js';
import { h, replace, field } from './dom.js';

let known = null;

/** The sites, asked once per page. */
function sites() {
  if (!known) known = get('/api/sites').catch(() => ({ site: null, sites: [] }));
  return known;
}

/** A hidden-until-needed Site field (`id` for its select); `value()` is
 * the chosen site, or '' for this server's own. */
export function siteChoice(id) {
  const sel = h('select', { id });
  const wrap = field('Site', sel);
  wrap.hidden = true;
  sites().then((v) => {
    if (!v.sites || v.sites.length < 2) return;
    replace(sel, v.sites.map((s) => h('option', { value: s, text: s === v.site ? `${s} (this site)` : s })));
    sel.value = v.site;
    wrap.hidden = false;
  });
  return { el: wrap, value: () => (wrap.hidden ? '' : sel.value) };
}
