#!/usr/bin/env python3
"""Memory and CPU of `gridscada serve` at scale (issue 19, part 5).

A generated plant of DEVICES Modbus TCP devices (one pymodbus server each, in
a child process) with TAGS tags in all, every one logged by the historian
(deadband 0.5 % of its 0-100 span), a high-limit alarm on every tenth tag,
and CLIENTS WebSocket clients on /api/live, each subscribed as the HMI is: to
one device's tags and to the alarm list (whole once, then its changes;
`--whole-alarm-lists` for the whole list each time, `--no-alarm-clients` for
tags only). Every second a tenth of the registers take a random step, so the
poller, the historian, the alarms and the push all have work. Every 10 s the
server's RSS and CPU are sampled, with its figures from /metrics (historian
backlog and drops, late scans, the share of a core alarm evaluation took,
standing alarms) and what the clients saw (the p99 of the push latency: the
client's clock minus each value's timestamp, taken when the scan's answer
arrived; the bytes of alarm messages). The verdict is whether RSS grew after
the first minute.

    target/test-venv/bin/python scripts/bench-memory.py --seconds 600
    (GRIDSCADA_BIN: the binary, target/release/gridscada by default)

The devices are served by the Rust `register_walker` example of the modbus
crate (`cargo build --release -p gridscada-modbus --example register_walker`,
WALKER_BIN to point elsewhere) when it is built: one lean process whose CPU
is a few percent of a core even at a million tags. `--peer python` uses
pymodbus servers in a child process instead (the walk is the same; at more
than about 100,000 tags they cannot keep up on 2 cores). The peer's CPU is
printed beside the server's.
"""
import argparse
import asyncio
import json
import os
import random
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.parse
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SPAN_RAW = 1000  # registers hold 0..1000, scale 0.1: 0..100 in engineering units


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def write_plant(folder, ports, per_device, http, storage="sqlite://gridscada.db"):
    files = []
    for d, port in enumerate(ports):
        name = f"d{d:02d}.toml"
        files.append(name)
        lines = [f'[[device]]\nname = "D{d:02d}"\nprotocol = "tcp"\naddress = "127.0.0.1:{port}"\n'
                 'unit_id = 1\nscan_ms = 1000\ntimeout_ms = 1000\nretries = 1\n']
        for a in range(per_device):
            lines.append(f'[[tag]]\nname = "D{d:02d}.T{a:04d}"\ndevice = "D{d:02d}"\n'
                         f'kind = "holding_register"\naddress = {a}\nscale = 0.1\n'
                         'history = { deadband = 0.5 }\n')
            if a % 10 == 0:
                lines.append('alarm = { hi = { limit = 52.0, priority = 500, deadband = 0.5 } }\n')
        with open(os.path.join(folder, name), "w") as f:
            f.write("\n".join(lines))
    with open(os.path.join(folder, "gridscada.toml"), "w") as f:
        f.write(f'tag_files = {json.dumps(files)}\n\n[server]\nhttp = "{http}"\n'
                f'data_dir = "data"\n\n[storage]\nurl = "{storage}"\n')


def serve_devices(ports, per_device):
    """The child process: one pymodbus server per port, registers walking."""
    from pymodbus.datastore import (ModbusSequentialDataBlock, ModbusServerContext,
                                    ModbusSlaveContext)
    from pymodbus.server import ModbusTcpServer

    rng = random.Random(19)
    contexts = []

    async def walk():
        while True:
            for slave, values in contexts:
                for a in rng.sample(range(per_device), per_device // 10):
                    values[a] = min(SPAN_RAW, max(0, values[a] + rng.randint(-10, 10)))
                slave.setValues(3, 0, values)
            await asyncio.sleep(1.0)

    async def main():
        servers = []
        for port in ports:
            block = ModbusSequentialDataBlock(0, [500] * (per_device + 1))
            slave = ModbusSlaveContext(hr=block)
            ctx = ModbusServerContext(slaves=slave, single=True)
            contexts.append((slave, [500] * per_device))
            servers.append(ModbusTcpServer(ctx, address=("127.0.0.1", port)))
        tasks = [asyncio.create_task(s.serve_forever()) for s in servers]
        tasks.append(asyncio.create_task(walk()))
        await asyncio.gather(*tasks)

    asyncio.run(main())


def proc_sample(pid):
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    cpu_s = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    rss_mib = 0.0
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                rss_mib = int(line.split()[1]) / 1024
    return cpu_s, rss_mib


def metrics(base):
    out = {}
    with urllib.request.urlopen(base + "/metrics", timeout=10) as r:
        for line in r.read().decode().splitlines():
            if line and not line.startswith("#"):
                k, _, v = line.rpartition(" ")
                try:
                    out[k] = float(v)
                except ValueError:
                    pass
    return out


def login(base, user, password):
    req = urllib.request.Request(base + "/api/session", method="POST",
                                 data=json.dumps({"username": user, "password": password}).encode(),
                                 headers={"Content-Type": "application/json", "Origin": base})
    with urllib.request.urlopen(req, timeout=10) as r:
        for k, v in r.headers.items():
            if k.lower() == "set-cookie":
                return v.split(";", 1)[0]
    raise RuntimeError("login gave no session cookie")


class LiveStats:
    """What the live clients saw: messages, and the push latency of each tag
    value (the client's clock minus the value's timestamp, which the poller
    stamps when the scan's answer arrives; server and clients share this
    machine's clock)."""

    def __init__(self, clients):
        self.tag_messages = [0] * clients
        self.alarm_messages = 0
        self.alarm_bytes = 0
        self.largest_alarm_message = 0
        self.window = []            # latencies (ms) since the last report
        self.histogram = {}         # all latencies, in 1 ms bins

    def take_window(self):
        w, self.window = self.window, []
        return w


def p99(values):
    if not values:
        return float("nan")
    values = sorted(values)
    return values[min(len(values) - 1, int(0.99 * len(values)))]


def histogram_p99(hist):
    total = sum(hist.values())
    seen = 0
    for ms in sorted(hist):
        seen += hist[ms]
        if seen >= 0.99 * total:
            return ms
    return float("nan")


async def ws_client(k, port, cookie, prefix, alarms, changes, stats, stop):
    import websockets
    async with websockets.connect(f"ws://127.0.0.1:{port}/api/live",
                                  additional_headers={"Cookie": cookie,
                                                      "Origin": f"http://127.0.0.1:{port}"},
                                  max_size=None) as ws:
        # The HMI's alarm footer is on every screen: its sockets ask for the
        # alarm list beside the screen's tags.
        await ws.send(json.dumps({"subscribe": {"prefixes": [prefix], "alarms": alarms,
                                                "alarm_changes": alarms and changes}}))
        while not stop.is_set():
            try:
                msg = await asyncio.wait_for(ws.recv(), 1.0)
            except asyncio.TimeoutError:
                continue
            if not isinstance(msg, str):
                continue
            if '"type":"tags"' in msg[:40]:
                stats.tag_messages[k] += 1
                m = json.loads(msg)
                if m.get("snapshot"):
                    continue
                now_ms = time.time() * 1000
                for v in m.get("values", ()):
                    ts = v.get("timestamp")
                    if isinstance(ts, (int, float)):
                        lat = now_ms - ts
                        stats.window.append(lat)
                        b = int(lat)
                        stats.histogram[b] = stats.histogram.get(b, 0) + 1
            elif '"heartbeat"' in msg[:80] or '"hello"' in msg[:80]:
                continue
            else:
                # The alarm list or its changes: counted, not parsed (the
                # client's own parsing must not hold the socket back).
                stats.alarm_messages += 1
                stats.alarm_bytes += len(msg)
                stats.largest_alarm_message = max(stats.largest_alarm_message, len(msg))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--tags", type=int, default=100_000)
    ap.add_argument("--devices", type=int, default=50)
    ap.add_argument("--clients", type=int, default=20)
    ap.add_argument("--seconds", type=int, default=600)
    ap.add_argument("--every", type=int, default=10)
    ap.add_argument("--whole-alarm-lists", action="store_true",
                    help="the clients ask for the whole alarm list each time it changes "
                         "(as the HMI did before 2026-12-01), not for its changes")
    ap.add_argument("--no-alarm-clients", action="store_true",
                    help="the live clients watch tags only (as runs before 2026-12-01 did)")
    ap.add_argument("--peer", choices=["rust", "python"], default=None,
                    help="who serves the devices (default: rust when the walker is built)")
    ap.add_argument("--storage", default="sqlite://gridscada.db",
                    help="the plant's [storage] url (a PostgreSQL database is emptied first)")
    ap.add_argument("--serve-devices", help=argparse.SUPPRESS)
    args = ap.parse_args()
    per_device = args.tags // args.devices
    if args.serve_devices:
        serve_devices([int(p) for p in args.serve_devices.split(",")], per_device)
        return
    binary = os.environ.get("GRIDSCADA_BIN", os.path.join(ROOT, "target", "release", "gridscada"))
    tmp = tempfile.mkdtemp(prefix="bench-memory-")
    # Distinct ports: the kernel may hand the same free port out twice
    # among hundreds of picks.
    picked = set()
    while len(picked) < args.devices + 1:
        picked.add(free_port())
    ports = sorted(picked)
    hport = ports.pop()
    base = f"http://127.0.0.1:{hport}"
    if args.storage.startswith("postgres"):
        # A fresh database of the bench's own on that server.
        u = urllib.parse.urlparse(args.storage)
        admin = u._replace(path="/postgres").geturl()
        for sql in ("DROP DATABASE IF EXISTS " + u.path[1:], "CREATE DATABASE " + u.path[1:]):
            subprocess.run(["psql", admin, "-q", "-c", sql], check=True)
    write_plant(tmp, ports, per_device, f"127.0.0.1:{hport}", args.storage)
    procs = []
    try:
        walker = os.environ.get("WALKER_BIN", os.path.join(ROOT, "target", "release", "examples",
                                                            "register_walker"))
        peer_kind = args.peer or ("rust" if os.path.exists(walker) else "python")
        if peer_kind == "rust":
            peer = subprocess.Popen([walker, str(per_device), ",".join(map(str, ports))],
                                    stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
            if peer.stdout.readline().strip() != "ready":
                sys.exit("the register walker did not start")
        else:
            peer = subprocess.Popen([sys.executable, __file__, "--tags", str(args.tags),
                                     "--devices", str(args.devices),
                                     "--serve-devices", ",".join(map(str, ports))])
        print(f"devices served by the {peer_kind} peer (pid {peer.pid})", flush=True)
        procs.append(peer)
        password = "bench-memory-" + str(random.randrange(10**9))
        # A supervisor opens the tag browser, so may read every tag (a
        # display user reads only what its screens show: here the devices'
        # Comm tags).
        subprocess.run([binary, "user", "add", "bench", "--role", "supervisor", "--config", tmp],
                       input=password + "\n", text=True, check=True, capture_output=True)
        # Start-up: `check` of the generated configuration, then `serve` to
        # its first /healthz answer (any status: it is up and answering).
        t0 = time.perf_counter()
        subprocess.run([binary, "check", tmp], check=True, capture_output=True)
        print(f"start-up: check of {args.tags} tags on {args.devices} devices took "
              f"{time.perf_counter() - t0:.1f} s", flush=True)
        t0 = time.perf_counter()
        server = subprocess.Popen([binary, "serve", "--config", tmp],
                                  stdout=open(f"{tmp}/serve.log", "w"), stderr=subprocess.STDOUT)
        procs.append(server)
        for _ in range(3000):
            try:
                urllib.request.urlopen(base + "/healthz", timeout=1)
                break
            except urllib.error.HTTPError:
                break
            except OSError:
                if server.poll() is not None:
                    sys.exit(f"serve exited: see {tmp}/serve.log")
                time.sleep(0.2)
        print(f"start-up: serve answered /healthz {time.perf_counter() - t0:.1f} s after it started",
              flush=True)
        cookies = [login(base, "bench", password) for _ in range((args.clients + 7) // 8)]
        stats = LiveStats(args.clients)
        loop = asyncio.new_event_loop()
        stop = asyncio.Event()

        async def clients():
            await asyncio.gather(*(ws_client(k, hport, cookies[k // 8],
                                             f"D{k % args.devices:02d}.",
                                             not args.no_alarm_clients,
                                             not args.whole_alarm_lists, stats, stop)
                                   for k in range(args.clients)))

        import threading
        t = threading.Thread(target=lambda: loop.run_until_complete(clients()), daemon=True)
        t.start()
        started = time.monotonic()
        last_cpu, last_t = proc_sample(server.pid)[0], started
        last_peer_cpu = proc_sample(peer.pid)[0]
        last_alarm_s = metrics(base).get("gridscada_alarm_evaluation_seconds_total", 0.0)
        series = []
        print(f"load average at the start: {open('/proc/loadavg').read().strip()}", flush=True)
        print("| t (s) | RSS (MiB) | CPU (% of one core) | tags | historian samples written | "
              "historian backlog | historian dropped | late scans | alarm evaluation (% of one core) | "
              "active alarms | live tag messages | push p99 (ms) | alarm messages (MiB) | "
              "peer CPU (%) | load 1 min |")
        print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
              flush=True)
        while time.monotonic() - started < args.seconds:
            time.sleep(args.every)
            now = time.monotonic()
            cpu, rss = proc_sample(server.pid)
            m = metrics(base)
            tags = m.get("gridscada_tags", float("nan"))
            written = m.get("gridscada_historian_samples_written_total", float("nan"))
            dropped = m.get("gridscada_historian_dropped_total", 0.0)
            late = sum(v for k, v in m.items() if k.startswith("gridscada_poll_late_scans_total"))
            backlog = m.get("gridscada_historian_buffered", float("nan"))
            alarm_s = m.get("gridscada_alarm_evaluation_seconds_total", 0.0)
            active = m.get('gridscada_alarms{which="active"}', float("nan"))
            peer_cpu = proc_sample(peer.pid)[0]
            pct = 100 * (cpu - last_cpu) / (now - last_t)
            peer_pct = 100 * (peer_cpu - last_peer_cpu) / (now - last_t)
            alarm_pct = 100 * (alarm_s - last_alarm_s) / (now - last_t)
            last_cpu, last_t, last_peer_cpu, last_alarm_s = cpu, now, peer_cpu, alarm_s
            row = (now - started, rss, pct, tags, written, backlog, dropped, late, alarm_pct,
                   active, sum(stats.tag_messages), p99(stats.take_window()),
                   stats.alarm_bytes / 2**20, peer_pct,
                   float(open("/proc/loadavg").read().split()[0]))
            series.append(row)
            print("| %.0f | %.1f | %.1f | %.0f | %.0f | %.0f | %.0f | %.0f | %.1f | %.0f | %d | %.0f "
                  "| %.1f | %.1f | %.2f |" % row, flush=True)
        after = [r for r in series if r[0] >= 60]
        if after:
            first, peak, end = after[0][1], max(r[1] for r in after), after[-1][1]
            print(f"\nRSS after the first minute: {first:.1f} MiB at {after[0][0]:.0f} s, "
                  f"peak {peak:.1f} MiB, end {end:.1f} MiB (growth {end - first:+.1f} MiB); "
                  f"mean CPU {sum(r[2] for r in after) / len(after):.1f} % of one core, "
                  f"of which alarm evaluation {sum(r[8] for r in after) / len(after):.1f} %")
        print(f"push latency over the run: p99 {histogram_p99(stats.histogram):.0f} ms of "
              f"{sum(stats.histogram.values())} tag values; {stats.alarm_messages} alarm messages "
              f"({stats.alarm_bytes / 2**20:.1f} MiB, the largest {stats.largest_alarm_message / 1024:.0f} KiB)")
        loop.call_soon_threadsafe(stop.set)
        t.join(10)
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
        print(f"(plant, log and data in {tmp})")


if __name__ == "__main__":
    main()
