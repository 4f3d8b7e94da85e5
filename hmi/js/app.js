// The HMI's frame: session, toolbar, clock, communication light, the live
// alarm footer, and the router that mounts one screen at a time.

import { api, get, del, post, setUnauthorizedHandler, enc, qs } from './api.js';
import { h, replace } from './dom.js';
import { fmtTime, setDisplay } from './format.js';
import { live } from './live.js';
import { claimHandover, watchPair } from './pair.js';
import { visibleEveryMs, watchExpiry } from './session.js';
import { toast, attempt, formDialog } from './ui.js';
import { AlarmFooter } from './components/alarmfooter.js';
import { beeper } from './components/beeper.js';
import { drawNavigation, groupOf } from './components/navigation.js';
import login from './screens/login.js';
import mainScreen from './screens/main.js';
import { panelScreen } from './screens/panel.js';
import microgrid from './screens/microgrid.js';
import units from './screens/units.js';
import alarms from './screens/alarms.js';
import alarmkpi from './screens/alarmkpi.js';
import events from './screens/events.js';
import reports from './screens/reports.js';
import trends from './screens/trends.js';
import users from './screens/users.js';
import tagBrowser from './screens/tags.js';
import devices from './screens/devices.js';
import editor from './screens/editor.js';
import simulation from './screens/simulation.js';
import network from './screens/network.js';
import { customScreen } from './screens/custom.js';

/** The built-in screens by id. Which exist, their order and labels come
 * from the server (/api/screens): the plant's panels, the microgrid screens
 * only with a microgrid, and the screens users drew. */
const BUILTIN = {
  main: mainScreen,
  microgrid,
  units,
  network,
  tags: tagBrowser,
  devices,
  alarms,
  alarmkpi,
  events,
  trends,
  reports,
  editor,
  users,
  simulation,
};

/** The screens of this plant the user may open: [id, label, module, group]. */
let SCREENS = [];
/** Shows the current screen in the navigation (set by renderToolbar). */
let markNavigation = () => {};

function moduleFor(entry) {
  if (entry.kind === 'panel') return panelScreen(entry.panel || entry.id);
  if (entry.kind === 'custom') return customScreen(entry.id.slice('custom:'.length));
  return BUILTIN[entry.id] || null;
}

const state = {
  session: { authenticated: false, user: null, role: 'guest', screens: [] },
  unmount: null,
  current: null,
  footer: null,
  offComm: null,
  offPair: null,
  modeTimer: null,
  disconnectedAt: null,
};

const $ = (id) => document.getElementById(id);

function allowed(name) { return state.session.authenticated && state.session.screens.includes(name); }

async function loadSession() {
  try {
    state.session = await get('/api/session');
    setDisplay(state.session.hmi);
  } catch (e) {
    state.session = { authenticated: false, user: null, role: 'guest', screens: [] };
    toast(`Cannot read the session: ${e.detail}`, 'error');
  }
  await loadScreens();
  renderFrame();
}

/** The plant's screens this user may open, in toolbar order. */
async function loadScreens() {
  SCREENS = [];
  if (!state.session.authenticated) return;
  try {
    const { screens } = await get('/api/screens');
    SCREENS = screens.filter((e) => e.allowed).map((e) => [e.id, e.label, moduleFor(e), groupOf(e)]).filter((e) => e[2]);
  } catch (e) {
    toast(`Cannot list the screens: ${e.detail}`, 'error');
  }
}

/** Reloads the screen list (after a screen was saved, renamed or deleted). */
export async function refreshScreens() {
  try { state.session = await get('/api/session'); } catch { /* keep the last session */ }
  await loadScreens();
  renderToolbar();
}

function renderToolbar() {
  markNavigation = drawNavigation($('toolbar'), SCREENS.filter(([id]) => allowed(id))
    .map(([id, label, , group]) => ({ id, label, group })));
  markNavigation(state.current);
}

function renderFrame() {
  const s = state.session;
  live.visibleMs = visibleEveryMs(s);
  renderToolbar();

  const box = $('user-box');
  if (s.authenticated) {
    replace(box,
      h('span', { class: 'user-name', id: 'current-user', title: `role ${s.role}, group ${s.group}`, text: s.user }),
      h('span', { class: 'user-role', text: s.role }),
      h('button', { type: 'button', class: 'btn btn-small', onclick: changeOwnPassword, text: 'Password' }),
      h('button', { type: 'button', class: 'btn btn-small', id: 'logout', onclick: logout, text: 'Log out' }));
  } else {
    replace(box, h('span', { class: 'user-name', id: 'current-user', text: 'Guest' }));
  }

  if (state.footer) { state.footer.dispose(); state.footer = null; }
  if (state.offComm) { state.offComm(); state.offComm = null; }
  clearInterval(state.modeTimer);
  state.modeTimer = null;
  $('mode-light').hidden = true;
  if (state.offPair) { state.offPair(); state.offPair = null; }
  $('pair-light').hidden = true;
  const footer = $('alarm-footer');
  if (s.authenticated) {
    live.start();
    footer.hidden = false;
    state.footer = new AlarmFooter(footer, s);
    state.footer.setScreen(state.current);
    startCommLight();
    watchPanelModes();
    if (s.pair) state.offPair = watchPair($('pair-light'));
  } else {
    live.stop();
    beeper.setUser(null); // a log out ends the horn's mute: it belonged to the session
    state.disconnectedAt = null;
    $('banner').hidden = true;
    document.body.classList.remove('disconnected');
    footer.hidden = true;
    replace(footer);
    const light = $('comm-light');
    light.className = 'comm-light comm-unknown';
    light.textContent = 'Comm: log in to see';
  }
  route();
}

/** The screen id of the hash: `#/id`, `#/custom:id`, `#/id/sub`, `#/id?query`. */
function hashScreen() {
  return (location.hash.match(/^#\/([\w-]+(?::[\w-]+)?)/) || [])[1];
}

function route() {
  const wanted = hashScreen();
  let id;
  if (!state.session.authenticated) id = 'login';
  else if (wanted && allowed(wanted)) id = wanted;
  else {
    id = SCREENS.map(([x]) => x).find(allowed) || 'none';
    if (wanted && wanted !== 'login') toast(`You may not open the "${wanted}" screen.`, 'error');
    if (id !== 'none' && location.hash !== `#/${id}`) { history.replaceState(null, '', `#/${id}`); }
  }
  mount(id);
}

function mount(id) {
  if (state.unmount) { try { state.unmount(); } catch (e) { console.error(e); } }
  state.unmount = null;
  state.current = id;
  const el = $('screen');
  replace(el);
  el.className = `screen screen-${id}`;
  markNavigation(id);
  if (state.footer) state.footer.setScreen(id);
  const entry = SCREENS.find(([x]) => x === id);
  const screen = id === 'login' ? login : entry && entry[2];
  document.title = `gridscada — ${entry ? entry[1] : id === 'login' ? 'Log in' : 'No screens'}`;
  if (!screen) {
    el.append(h('p', { class: 'empty', text: 'Your group may not open any screen. Ask an administrator.' }));
    return;
  }
  // After a log in, focus goes to the screen's content (not the page's body).
  const onLogin = async () => { await loadSession(); focusContent(); };
  const ctx = { session: state.session, onLogin, rerender: () => mount(id), refreshScreens };
  try {
    state.unmount = screen.mount(el, ctx) || null;
  } catch (e) {
    console.error(e);
    el.append(h('p', { class: 'error', text: `This screen failed to draw: ${e.message}` }));
  }
}

async function logout() {
  // The live socket closes first: closed by the server when the session
  // ends, it could reconnect, and be refused, before the session reloads.
  // (loadSession starts it again if the log out failed.)
  live.stop();
  await attempt('Log out', () => del('/api/session'));
  history.replaceState(null, '', '#/login');
  await loadSession();
}

async function changeOwnPassword() {
  const data = await formDialog('Change my password', (f) => {
    f.append(
      h('label', { class: 'field' }, h('span', { class: 'field-label', text: 'Current password' }),
        h('input', { type: 'password', name: 'current', required: true, autocomplete: 'current-password' })),
      h('label', { class: 'field' }, h('span', { class: 'field-label', text: 'New password' }),
        h('input', { type: 'password', name: 'password', required: true, minlength: 8, autocomplete: 'new-password' })));
  }, { submitLabel: 'Change password' });
  if (!data) return;
  const ok = await attempt('Change password', () => post(`/api/users/${enc(state.session.user)}/password`,
    { password: data.get('password'), current_password: data.get('current') }));
  if (ok !== undefined) toast('Password changed.', 'ok');
}

// The communication light names every controller whose Comm.Connected is not true.
async function startCommLight() {
  const light = $('comm-light');
  let tags = [];
  try {
    // Only the devices' status tags, found on the server (a plant may have 100,000 tags).
    const list = await get(`/api/tags${qs({ search: '.comm.connected', limit: 1000 })}`);
    tags = list.tags.map((t) => t.name).filter((n) => n.endsWith('.Comm.Connected'));
  } catch (e) {
    light.className = 'comm-light comm-unknown';
    light.textContent = 'Comm: unknown';
    light.title = e.detail;
    return;
  }
  const draw = () => {
    if (!live.connected) {
      light.className = 'comm-light comm-lost';
      light.textContent = live.silent ? 'Server not answering' : 'Server connection lost';
      light.title = live.silent
        ? 'The server stopped sending its heartbeat: values are not live; reconnecting.'
        : 'The live connection to the server is down; reconnecting.';
      return;
    }
    const lost = tags.filter((t) => {
      const v = live.get(t);
      return !v || v.value !== true || (v.quality && v.quality.code === 'bad');
    }).map((t) => t.slice(0, -'.Comm.Connected'.length));
    if (lost.length === 0) {
      light.className = 'comm-light comm-ok';
      light.textContent = 'Comm OK';
      light.title = `All ${tags.length} controllers reachable`;
    } else {
      light.className = 'comm-light comm-lost';
      light.textContent = `Comm lost: ${lost.join(', ')}`;
      light.title = `No communication with ${lost.join(', ')}`;
    }
  };
  const offWant = live.want({ tags });
  const offTags = live.onTags(draw);
  const offStatus = live.onStatus(draw);
  draw();
  state.offComm = () => { offWant(); offTags(); offStatus(); };
}

// Manual mode turns automatic isolation off: the header names every panel in it.
function watchPanelModes() {
  const light = $('mode-light');
  const check = async () => {
    let panels;
    try { ({ panels } = await get('/api/panels')); } catch { return; } // no panels, or none readable
    const manual = panels.filter((p) => p.mode === 'manual');
    light.hidden = manual.length === 0;
    light.textContent = manual.length ? `MANUAL: ${manual.map((p) => p.name).join(', ')}` : '';
    light.title = manual.length ? `Automatic fault isolation is off on ${manual.map((p) => p.name).join(', ')}` : '';
  };
  check();
  state.modeTimer = setInterval(check, 3000);
}

// The communication light opens the devices screen (for those who may).
function wireCommLight() {
  const light = $('comm-light');
  const open = () => { if (allowed('devices')) location.hash = '#/devices'; };
  light.addEventListener('click', open);
  light.addEventListener('keydown', (e) => { if (e.key === 'Enter' || e.key === ' ') { e.preventDefault(); open(); } });
  light.tabIndex = 0;
  light.title = 'Communication status: open the devices screen';
}

/** Moves focus to the screen's content, as "Skip to content" does. */
function focusContent() {
  const el = $('screen');
  el.focus({ preventScroll: true });
  el.scrollIntoView({ block: 'start' });
}

// "Skip to content" focuses the content of the screen on view: the hash
// belongs to the router, so following the link's #screen would open Main.
function wireSkipLink() {
  document.querySelector('.skip-link').addEventListener('click', (e) => {
    e.preventDefault();
    focusContent();
  });
}

// The dark theme for control rooms: a toggle in the header, kept in this
// browser (js/theme.js sets it before the first paint).
const THEME_KEY = 'gridscada.theme';
function wireThemeToggle() {
  const btn = $('theme-toggle');
  const draw = () => btn.setAttribute('aria-pressed', String(document.documentElement.dataset.theme === 'dark'));
  btn.addEventListener('click', () => {
    const dark = document.documentElement.dataset.theme !== 'dark';
    if (dark) document.documentElement.dataset.theme = 'dark';
    else delete document.documentElement.dataset.theme;
    try { localStorage.setItem(THEME_KEY, dark ? 'dark' : 'light'); } catch { /* storage disabled: this page only */ }
    draw();
    window.dispatchEvent(new CustomEvent('gridscada-theme'));
  });
  draw();
}

function tickClock() {
  const d = new Date();
  const el = $('clock');
  el.textContent = fmtTime(d.getTime());
  el.setAttribute('datetime', d.toISOString());
}

// Shows that the live connection was lost, and when it came back.
function watchConnection() {
  const banner = $('banner');
  let hideTimer = null;
  live.onStatus((connected) => {
    clearTimeout(hideTimer);
    document.body.classList.toggle('disconnected', !connected && live.stopped === false);
    if (!connected && !live.stopped) {
      if (!state.disconnectedAt) state.disconnectedAt = Date.now();
      banner.hidden = false;
      banner.className = 'banner banner-lost';
      banner.textContent = `${live.silent ? 'The server is not answering' : 'Disconnected from the server'} since ${fmtTime(state.disconnectedAt)}: reconnecting. Values shown are not live.`;
    } else if (connected && state.disconnectedAt) {
      const secs = Math.round((Date.now() - state.disconnectedAt) / 1000);
      state.disconnectedAt = null;
      banner.hidden = false;
      banner.className = 'banner banner-ok';
      banner.textContent = `Reconnected at ${fmtTime(Date.now())} after ${secs} s disconnected; live values resumed.`;
      hideTimer = setTimeout(() => { banner.hidden = true; }, 10_000);
    } else {
      banner.hidden = true;
    }
  });
}

live.onSessionEnded = () => {
  toast('Your session ended. Please log in again.', 'error');
  loadSession();
};
// While reconnecting, find out whether the session itself is gone.
live.onConnectFailed = async () => {
  let s;
  try { s = await get('/api/session'); } catch { return; } // server still down: keep trying
  if (state.session.authenticated && s && !s.authenticated) {
    toast('Your session ended (the server may have restarted). Please log in again.', 'error');
    loadSession();
  }
};
setUnauthorizedHandler(() => {
  if (state.session.authenticated) {
    toast('Your session ended. Please log in again.', 'error');
    loadSession();
  }
});

// A change of the hash's query (e.g. the trend's pens) stays on the screen.
window.addEventListener('hashchange', () => { if (state.session && hashScreen() !== state.current) route(); });
tickClock();
setInterval(tickClock, 1000);
wireCommLight();
wireSkipLink();
wireThemeToggle();
watchConnection();
watchExpiry($('session-warning'), () => state.session, () => api('GET', '/api/session', undefined, { user: true }));
claimHandover().then(loadSession);
