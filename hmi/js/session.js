// Session expiry, as the HMI sees it: the server ends a session after
// `idle_timeout_s` without activity (GET /api/session; null: never). Any
// request counts as activity, and so does the live connection's "visible"
// message while a screen is on view, so a watched screen never idles out.
// A screen left hidden (or whose live connection is down) is warned
// `warn_s` before it would, with a button that keeps the session.

let lastActivity = Date.now();

/** Something the server counts as activity happened now. */
export function noteActivity() { lastActivity = Date.now(); }

/** How often a visible screen should tell the server it is watched. */
export function visibleEveryMs(session) {
  const idle = session && session.idle_timeout_s;
  return typeof idle === 'number' && idle > 0 ? Math.max(1000, Math.min(60_000, (idle * 1000) / 3)) : 60_000;
}

/**
 * Shows a warning in `el` when the session is about to idle out. `session()`
 * gives the current session; `keep()` is a request that counts as activity.
 */
export function watchExpiry(el, session, keep) {
  const button = document.createElement('button');
  button.type = 'button';
  button.className = 'btn btn-small';
  button.id = 'session-keep';
  button.textContent = 'Stay logged in';
  const text = document.createElement('span');
  text.id = 'session-warning-text';
  el.replaceChildren(text, ' ', button);
  button.addEventListener('click', async () => {
    try { await keep(); noteActivity(); } catch { /* the 401 handler takes over */ }
    el.hidden = true;
  });
  const tick = () => {
    const s = session();
    const idle = s && s.authenticated ? s.idle_timeout_s : null;
    if (typeof idle !== 'number') { el.hidden = true; return; }
    const left = Math.ceil((idle * 1000 - (Date.now() - lastActivity)) / 1000);
    const warn = typeof s.warn_s === 'number' ? s.warn_s : 60;
    if (left > warn) { el.hidden = true; return; }
    text.textContent = left > 0
      ? `Your session ends in ${left} s for inactivity.`
      : 'Your session has ended for inactivity.';
    el.hidden = false;
  };
  tick();
  return setInterval(tick, 1000);
}
