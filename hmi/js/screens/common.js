// Look-ups shared by several screens.

import { get } from '../api.js';
import { noteTags } from '../format.js';

let tagListCache = null;

/** All tag metadata (name, units, kind, description...), fetched once per page load. */
export async function tagList() {
  if (!tagListCache) {
    tagListCache = get('/api/tags').then((r) => noteTags(r.tags)).catch((e) => { tagListCache = null; throw e; });
  }
  return tagListCache;
}

/**
 * The names of the configured tags, as a set: a screen draws a signal only
 * where the plant configures it ("?" is for a configured signal whose value
 * is not known, never for one that does not exist).
 */
export async function configuredTags() {
  return new Set((await tagList()).map((t) => t.name));
}

/** The tag-name prefix of a panel (the API names the panel by id, the tags by prefix). */
export function panelPrefix(panel) {
  return panel.prefix || String(panel.id).toUpperCase();
}

/** The devices (I/O modules, analyzer) under a prefix, from their Comm.Connected tags. */
export async function devicesUnder(prefix) {
  const tags = await tagList();
  return tags.map((t) => t.name)
    .filter((n) => n.startsWith(`${prefix}.`) && n.endsWith('.Comm.Connected'))
    .map((n) => n.slice(0, -'.Comm.Connected'.length))
    .sort();
}
