// Test fixtures made through the API: a Guest-role user, panel clean-up.

import { requireOk, until } from './lib.js';

export const GUEST = { user: 'e2e-guest', password: 'guest-password-e2e-1' };

/** Makes sure a Guest-role user exists (the demo prints none); returns its credentials. */
export async function ensureGuest(api) {
  const r = await api.call('POST', '/api/users', { name: GUEST.user, role: 'guest', password: GUEST.password });
  if (r.status !== 201 && r.status !== 409) requireOk(r, 'creating the guest user');
  if (r.status === 409) requireOk(await api.call('POST', `/api/users/${GUEST.user}/password`, { password: GUEST.password }), 'setting the guest password');
  return GUEST;
}

/** Repairs any simulated fault on the panel, sets Auto, resets, and waits until every breaker is closed. */
export async function restorePanel(api, panel, zones = 4) {
  for (let z = 1; z <= zones; z++) await api.call('DELETE', `/api/sim/faults/${panel}/${z}`);
  await api.call('POST', `/api/panels/${panel}/mode`, { mode: 'auto' });
  await api.call('POST', `/api/panels/${panel}/reset`);
  return until(`panel ${panel} healthy with all breakers closed`, async () => {
    const r = await api.call('GET', `/api/panels/${panel}`);
    const s = r.body;
    if (!s || !s.breakers) return false;
    if (s.lockout || s.step === 'lockout') { await api.call('POST', `/api/panels/${panel}/reset`); return false; }
    return Object.values(s.breakers).every((b) => b.closed) && s.step === 'idle' ? s : false;
  }, 30_000, 500);
}
