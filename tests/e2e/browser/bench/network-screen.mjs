// Benchmark: the network screen's colours reaching the browser after a
// switch changes (docs/BENCHMARKS.md, "Network topology"). Figures only, no
// limit: scripts/bench-network-screen.sh runs it against a generated
// 10,000-device network and against the demo's ring, in the same run.
//
// Against one running `gridscada demo` (GRIDSCADA_URL, GRIDSCADA_CREDENTIALS):
// opens the network screen as the operator in Chromium, then for each round
// opens a device by select-before-operate through the API and closes it
// again. Each time it takes the sections the preview names, watches them on
// the screen (a MutationObserver on their data-state, by the browser's
// clock), and measures from the device's status change (the timestamp of
// the poll that read the new position, the server's clock: one machine) to
// the last of them showing its new state. Prints one JSON line.
//
// Usage: node bench/network-screen.mjs LABEL ROUNDS DEVICE [DEVICE...]
import { launch, login, credentials, requireOk, until, BASE } from '../lib.js';
import { apiAs, state, operateApi } from '../network/net.js';

const [label, roundsArg, ...devices] = process.argv.slice(2);
const rounds = Number(roundsArg);
if (!label || !(rounds > 0) || devices.length === 0) {
  console.error('usage: node bench/network-screen.mjs LABEL ROUNDS DEVICE [DEVICE...]');
  process.exit(2);
}

const pct = (xs, p) => {
  const v = [...xs].sort((a, b) => a - b);
  return v.length ? v[Math.min(v.length - 1, Math.ceil((p / 100) * v.length) - 1)] : null;
};

const api = await apiAs('supervisor');
const model = requireOk(await api.call('GET', '/api/network'), 'the network model');
const statusOf = new Map(model.switches.map((w) => [w.id, (w.status_tags || [])[0]]));
for (const d of devices) if (!statusOf.get(d)) throw new Error(`no device ${d} with a status tag in the network`);
await until('every section of known state and every customer on supply', async () => {
  const u = await state(api, 'NET.CustomersUnknown');
  const off = await state(api, 'NET.CustomersOff');
  return u && u.value === 0 && off && off.value === 0;
}, 120_000, 500);

const c = credentials().operator;
const b = await launch(`bench-network-${label}`);
const out = { label, sections: model.sections.length, devices: model.switches.length, rounds, open_ms: [], close_ms: [] };
try {
  await b.page.setViewportSize({ width: 1600, height: 1000 });
  await login(b.page, c.user, c.password);
  const t0 = Date.now();
  await b.page.goto(`${BASE}/#/network`);
  // Loaded: every section drawn and coloured from its live tag.
  await b.page.waitForFunction((n) => {
    const els = document.querySelectorAll('.net-section[data-state]');
    return els.length === n && [...els].every((e) => e.dataset.state !== 'UNKNOWN');
  }, model.sections.length, { timeout: 300_000, polling: 250 });
  out.screen_load_ms = Date.now() - t0;

  // One operation: the sections the preview names, watched until each shows
  // `target`; answers the latency from the status change in ms.
  const operate = async (device, operation, target) => {
    const p = requireOk(await api.call('GET', `/api/network/preview?device=${device}&operation=${operation}`), 'preview');
    const ids = operation === 'open' ? p.lose_supply : p.gain_supply;
    if (!ids || ids.length === 0) throw new Error(`${operation} ${device} changes no section's supply`);
    await b.page.evaluate(({ ids, target }) => {
      window.__seenAt = {};
      window.__observers?.forEach((o) => o.disconnect());
      window.__observers = ids.map((id) => {
        const el = document.querySelector(`.net-section[data-section="${id}"]`);
        const o = new MutationObserver(() => {
          if (el.dataset.state === target && !window.__seenAt[id]) window.__seenAt[id] = Date.now();
        });
        o.observe(el, { attributes: true, attributeFilter: ['data-state'] });
        return o;
      });
    }, { ids, target });
    requireOk(await operateApi(api, device, operation), `${operation} ${device}`);
    await b.page.waitForFunction((ids) => ids.every((id) => window.__seenAt[id]), ids, { timeout: 30_000, polling: 50 });
    const seen = await b.page.evaluate(() => Math.max(...Object.values(window.__seenAt)));
    const status = await state(api, statusOf.get(device));
    if (status.value !== (operation === 'close')) throw new Error(`${device}'s status reads ${status.value} after ${operation}`);
    return { ms: seen - status.timestamp, sections: ids.length };
  };

  for (let r = 0; r < rounds; r++) {
    const device = devices[r % devices.length];
    const o = await operate(device, 'open', 'DEAD');
    out.open_ms.push(o.ms);
    out.sections_changed = o.sections;
    const cl = await operate(device, 'close', 'ENERGISED');
    out.close_ms.push(cl.ms);
  }
} finally {
  await b.close();
}
const all = [...out.open_ms, ...out.close_ms];
out.p50_ms = pct(all, 50);
out.p99_ms = pct(all, 99);
out.max_ms = Math.max(...all);
console.log(JSON.stringify(out));
