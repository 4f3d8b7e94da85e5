// A redundant pair (docs/REDUNDANCY.md): the header names the server this
// HMI talks to, whether it is the active one, and whether the pair is whole;
// and the HMI moves to the active server on a failover.
//
// It follows `/api/pair`, on a server of a pair only (`/api/session` says
// `pair`; a server alone shows nothing). The server's answer follows its own
// leadership, so the header stops saying "active" as soon as the server
// steps down; an answer that does not come within a poll counts as no
// answer. When the server it was on stops being active, or stops answering
// for longer than a takeover, it goes to the active server's configured
// address (or, with no answer, to the next server of the pair). An HMI
// opened on a standby stays there, read-only, with a link to the active
// server.
//
// The session cookie belongs to this server's host, and the other server
// may be another host: so the HMI keeps a failover ticket of this server
// (renewed every minute, `/api/session/handover`) and hands it to the
// other one in the address it goes to; `claimHandover` there turns it into
// a session, so the operator stays logged in.

import { api, ApiError, post } from './api.js';

const EVERY_MS = 2000;
/** No answer this long: the server is taken for dead (more than a takeover). */
const DEAD_MS = 8000;
/** How often the failover ticket is renewed (it lasts three minutes). */
const TICKET_EVERY_MS = 60_000;
/** The address parameter that carries a ticket to the other server. */
const HANDOVER = 'handover';

/** Starts following the pair; returns the stop function. */
export function watchPair(light) {
  let last = null;          // the last view of the pair
  let wasActive = false;    // this server was the active one
  let silentSince = null;
  let stopped = false;
  let ticket = null;        // this login's failover ticket
  let ticketAt = 0;

  const renewTicket = async () => {
    if (Date.now() - ticketAt < TICKET_EVERY_MS) return;
    try {
      const t = await post('/api/session/handover', ticket ? { previous: ticket } : {});
      ticket = t.ticket;
      ticketAt = Date.now();
    } catch { /* the next check tries again */ }
  };

  const go = (url, why) => {
    if (!url || stopped) return;
    const target = new URL(url);
    if (target.origin === location.origin) return;
    stopped = true;
    light.textContent = `Failover: going to ${why}…`;
    const carry = ticket ? `?${HANDOVER}=${encodeURIComponent(ticket)}` : '';
    location.href = `${target.origin}${location.pathname}${carry}${location.hash}`;
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
      const v = await api('GET', '/api/pair', undefined, { timeoutMs: EVERY_MS });
      silentSince = null;
      last = v;
      draw(v);
      await renewTicket();
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

/**
 * On an HMI opened by a failover from the other server: logs in here with
 * the ticket it carried, and drops it from the address (it is good once).
 */
export async function claimHandover() {
  const params = new URLSearchParams(location.search);
  const ticket = params.get(HANDOVER);
  if (!ticket) return;
  params.delete(HANDOVER);
  const rest = params.toString();
  history.replaceState(null, '', `${location.pathname}${rest ? `?${rest}` : ''}${location.hash}`);
  try {
    await post('/api/session/handover/claim', { ticket });
  } catch { /* expired or used: the login page asks */ }
}
