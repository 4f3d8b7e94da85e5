// A redundant pair (docs/REDUNDANCY.md): the header names the server this
// HMI talks to, whether it is the active one, and whether the pair is whole;
// and the HMI moves to the active server on a failover.
//
// It follows `/api/pair` (404 on a server alone: nothing is shown). When the
// server it was on stops being active, or stops answering for longer than a
// takeover, it goes to the active server's configured address (or, with no
// answer, to the next server of the pair). An HMI opened on a standby stays
// there, read-only, with a link to the active server.

import { api, ApiError } from './api.js';

const EVERY_MS = 2000;
/** No answer this long: the server is taken for dead (more than a takeover). */
const DEAD_MS = 8000;

/** Starts following the pair; returns the stop function. */
export function watchPair(light) {
  let last = null;          // the last view of the pair
  let wasActive = false;    // this server was the active one
  let silentSince = null;
  let stopped = false;

  const go = (url, why) => {
    if (!url || stopped) return;
    const target = new URL(url);
    if (target.origin === location.origin) return;
    stopped = true;
    light.textContent = `Failover: going to ${why}…`;
    location.href = `${target.origin}${location.pathname}${location.hash}`;
  };

  const draw = (v) => {
    const me = v.server;
    light.hidden = false;
    light.classList.toggle('pair-degraded', !v.healthy);
    const health = v.healthy ? 'pair OK' : 'pair degraded';
    if (v.role === 'active') {
      light.replaceChildren(`Server ${me}: active · ${health}`);
      light.title = `This server commands the plant (lease epoch ${v.epoch}).`;
    } else {
      light.replaceChildren(`Server ${me}: standby · `);
      if (v.active && v.active_url) {
        const a = document.createElement('a');
        a.href = `${new URL(v.active_url).origin}${location.pathname}${location.hash}`;
        a.textContent = `active: ${v.active}`;
        light.append(a);
      } else {
        light.append('no active server');
      }
      light.title = 'This server is read-only: commands go to the active server.';
    }
  };

  const check = async () => {
    if (stopped) return;
    try {
      const v = await api('GET', '/api/pair');
      silentSince = null;
      last = v;
      draw(v);
      if (v.role === 'active') wasActive = true;
      else if (wasActive && v.active_url) go(v.active_url, `the active server ${v.active}`);
    } catch (e) {
      if (e instanceof ApiError && e.status === 404) { stop(); return; } // not a pair
      if (!last) return;
      silentSince = silentSince || Date.now();
      light.classList.add('pair-degraded');
      light.replaceChildren(`Server ${last.server}: not answering`);
      if (Date.now() - silentSince > DEAD_MS && wasActive) {
        const next = last.servers.find((s) => s.name !== last.server);
        if (next) go(next.url, `server ${next.name}`);
      }
    }
  };
  const timer = setInterval(check, EVERY_MS);
  check();
  function stop() {
    stopped = true;
    clearInterval(timer);
    light.hidden = true;
  }
  return stop;
}
