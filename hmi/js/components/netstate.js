// How a network section's state looks, wherever it is drawn (the network
// screen, a drawn screen's line bound to a section): the palette of
// docs/HMI_STYLE.md "Network colours", as CSS classes.

/** The CSS class of a section state (NET.Sec.<id>.State). */
export function stateClass(state) {
  switch (state) {
    case 'ENERGISED': return 'net-energised';
    case 'DEAD': return 'net-dead';
    case 'EARTHED': return 'net-earthed';
    case 'ENERGISED+EARTHED': return 'net-energised-earthed';
    default: return 'net-unknown';
  }
}

/** Every state class, to remove before adding the current one. */
export const STATE_CLASSES = ['net-energised', 'net-dead', 'net-earthed', 'net-energised-earthed', 'net-unknown'];

/** The network's voltage levels, highest first (from GET /api/network). */
export function levelsOf(model) {
  return [...new Set(model.sections.map((x) => x.kv).filter((k) => typeof k === 'number'))].sort((a, b) => b - a);
}

/** The CSS class of a section's voltage level: its energised colour. */
export function levelClass(model, levels, sectionId) {
  const kv = (model.sections.find((x) => x.id === sectionId) || {}).kv;
  const i = levels.indexOf(kv);
  return i < 0 ? 'net-lvl-x' : `net-lvl-${Math.min(i, 3)}`;
}
