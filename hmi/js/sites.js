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

/** A hidden-until-needed Site field (`id` for its select), calling
 * `onChange` when another site is chosen; `value()` is the chosen site, or
 * '' for this server's own; `other()` whether it is another site than this
 * server's (whose live values are then not its). */
export function siteChoice(id, onChange) {
  const sel = h('select', { id });
  if (onChange) sel.addEventListener('change', onChange);
  const wrap = field('Site', sel);
  wrap.hidden = true;
  let own = null;
  sites().then((v) => {
    if (!v.sites || v.sites.length < 2) return;
    replace(sel, v.sites.map((s) => h('option', { value: s, text: s === v.site ? `${s} (this site)` : s })));
    sel.value = v.site;
    own = v.site;
    wrap.hidden = false;
  });
  return {
    el: wrap,
    value: () => (wrap.hidden ? '' : sel.value),
    other: () => !wrap.hidden && sel.value !== own,
  };
}
