#!/usr/bin/env python3
"""Telecontrol benchmarks (issue 30), each against a peer in the same run:

1. IEC 104 general interrogation of 20,000 points from a lib60870 (c104)
   station: gridscada's controlling station against c104's own client, each
   timed from the C_IC the station receives to the interrogation's end
   (gridscada: every point in its tag database; c104: ACT_TERM received),
   with the CPU each process spent.
2. IEC 104 spontaneous data at 5,000 points/s for 10 s from the same
   station: the CPU gridscada spends taking it in (tag database and its
   subscribers: historian, alarms, live push), against c104's client (a
   process of its own) taking the same stream at the same time.
3. DNP3 integrity poll of 10,000 points from gridscada's simulated
   outstation (`gridscada sim`): gridscada's master against dnp3py's
   master, time and CPU.
3b. DNP3 events at 2,000/s (1,000 analog inputs changing round-robin,
   served by this crate's outstation in `examples/dnp3_event_source`):
   events taken and CPU, gridscada's master (event polls every 0.2 s, and
   unsolicited responses) against dnp3py's master (class polls every
   0.2 s), each fed by a source of its own.
4. 50 IEC 104 stations of 2,000 points each (simulated by `gridscada sim`)
   on one `gridscada serve`: time until every point is Good, then RSS and
   CPU over 30 s.

    GRIDSCADA_BIN=target/release/gridscada python3 scripts/bench-telecontrol.py [iec104] [dnp3] [events] [stations]

DNP3_EVENT_SOURCE (default target/release/examples/dnp3_event_source):
cargo build --release -p gridscada-dnp3 --example dnp3_event_source.

Needs the test venv (c104, dnp3py). Prints one line per figure; run it on
an otherwise idle machine.
"""

import asyncio
import json
import os
import re
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

import c104

BIN = os.environ.get("GRIDSCADA_BIN", "target/release/gridscada")
EVENT_SOURCE = os.environ.get("DNP3_EVENT_SOURCE", "target/release/examples/dnp3_event_source")

# The peer client of the spontaneous stream, a process of its own so its CPU
# is its own: c104's client with the station's points, counting the
# spontaneous M_ME_NC ASDUs it receives. "MARK" on stdin: it prints
# "COUNT n CPU seconds".
C104_CLIENT = r"""
import sys, time, c104
port, points = int(sys.argv[1]), int(sys.argv[2])
count = [0]
cl = c104.Client(tick_rate_ms=50)
conn = cl.add_connection(ip="127.0.0.1", port=port, init=c104.Init.MUTED)
st = conn.add_station(common_address=1)
for i in range(1, points + 1):
    st.add_point(io_address=i, type=c104.Type.M_ME_NC_1)
def on_raw(connection: c104.Connection, data: bytes) -> None:
    if len(data) > 8 and data[6] == 13 and data[8] & 0x3F == 3:
        count[0] += 1
conn.on_receive_raw(callable=on_raw)
cl.start()
end = time.time() + 20
while not conn.is_connected and time.time() < end:
    time.sleep(0.05)
conn.unmute()
while conn.state != c104.ConnectionState.OPEN and time.time() < end:
    time.sleep(0.05)
print("READY" if conn.state == c104.ConnectionState.OPEN else "NOT OPEN", flush=True)
for line in sys.stdin:
    print(f"COUNT {count[0]} CPU {time.process_time():.6f}", flush=True)
cl.stop()
"""


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    p = s.getsockname()[1]
    s.close()
    return p


def port_open(port):
    try:
        socket.create_connection(("127.0.0.1", port), 0.2).close()
        return True
    except OSError:
        return False


def cpu_s(pid):
    """CPU seconds of process `pid`'s live threads, to the nanosecond
    (/proc/PID/task/*/schedstat; /proc/PID/stat counts 10 ms ticks)."""
    total = 0
    for t in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{t}/schedstat") as f:
                total += int(f.read().split()[0])
        except (OSError, ValueError, IndexError):
            pass
    return total / 1e9


def rss_mib(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return 0.0


def wait_for(cond, timeout, step=0.05):
    end = time.time() + timeout
    while time.time() < end:
        v = cond()
        if v:
            return v
        time.sleep(step)
    return None


def metric(text, name, device):
    m = re.search(rf'^{name}{{device="{re.escape(device)}"}} ([0-9.e+-]+)$', text, re.M)
    return float(m.group(1)) if m else None


def fetch(url, timeout=10):
    """The body, or "" while the server is not up."""
    try:
        with urllib.request.urlopen(url, timeout=timeout) as r:
            return r.read().decode()
    except OSError:
        return ""


class Proxy:
    """A TCP relay that notes when a DNP3 integrity poll (a READ with a
    class 0 header, g60v1 qualifier 0x06) passes toward the outstation,
    and the CPU of process `pid` at that moment."""

    def __init__(self, target_port, pid=None):
        self.target = target_port
        self.pid = pid
        self.polls = []  # (perf_counter, cpu of pid)
        self.sock = socket.socket()
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.sock.listen(4)
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        while True:
            try:
                c, _ = self.sock.accept()
            except OSError:
                return
            u = socket.create_connection(("127.0.0.1", self.target))
            for a, b, up in ((c, u, True), (u, c, False)):
                threading.Thread(target=self._pipe, args=(a, b, up), daemon=True).start()

    def _pipe(self, a, b, up):
        while True:
            try:
                data = a.recv(65536)
            except OSError:
                data = b""
            if not data:
                for s in (a, b):
                    try:
                        s.close()
                    except OSError:
                        pass
                return
            if up and b"\x3c\x01\x06" in data:
                self.polls.append((time.perf_counter(), cpu_s(self.pid) if self.pid else 0.0))
            b.sendall(data)


MAIN = """
tag_files = ["tags.toml"]
[server]
http = "127.0.0.1:{http}"
data_dir = "data"
[storage]
url = "sqlite://gridscada.db"
"""


def demo(plant, http, data, real):
    args = [BIN, "demo", "--config", plant, "--http", f"127.0.0.1:{http}", "--data", data]
    for r in real:
        args += ["--real-device", r]
    return subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def plant_dir(tags):
    d = tempfile.mkdtemp(prefix="gridscada-bench-tc-")
    http = free_port()
    with open(os.path.join(d, "gridscada.toml"), "w") as f:
        f.write(MAIN.format(http=http))
    with open(os.path.join(d, "tags.toml"), "w") as f:
        f.write(tags)
    return d, http


# --- 1 and 2: IEC 104 -------------------------------------------------------

def iec104(points=20_000, rate=5_000, seconds=10):
    port = free_port()
    server = c104.Server(ip="127.0.0.1", port=port, max_connections=4)
    st = server.add_station(common_address=1)
    pts = []
    for i in range(1, points + 1):
        p = st.add_point(io_address=i, type=c104.Type.M_ME_NC_1)
        p.value = float(i)
        pts.append(p)
    gi_seen = []

    # A C_IC (type 100) with cause 6, received: the interrogation starts.
    def on_raw(server: c104.Server, data: bytes) -> None:
        if len(data) > 8 and data[2] & 1 == 0 and data[6] == 100 and data[8] & 0x3F == 6:
            gi_seen.append(time.perf_counter())
    server.on_receive_raw(callable=on_raw)
    server.start()

    tags = [f'[[device]]\nname = "B"\nprotocol = "iec104"\naddress = "127.0.0.1:{port}"\n'
            f'[device.iec104]\ncommon_address = 1\ninterrogation_period_s = 15\n']
    for i in range(1, points + 1):
        tags.append(f'[[tag]]\nname = "B.M{i}"\ndevice = "B"\ntype = "f32"\n'
                    f'iec104 = {{ ioa = {i}, point = "M_ME_NC" }}\n')
    d, http = plant_dir("\n".join(tags))
    gs = demo(d, http, os.path.join(d, "data"), ["B"])
    base = f"http://127.0.0.1:{http}"
    try:
        gis = lambda: metric(fetch(f"{base}/metrics"), "gridscada_iec104_interrogations_total", "B") or 0
        if not wait_for(lambda: gis() >= 1, 120, 0.2):
            print("iec104: gridscada never finished its first interrogation", flush=True)
            return
        # The periodic interrogation, in steady state.
        n0, seen0 = gis(), len(gi_seen)
        wait_for(lambda: len(gi_seen) > seen0, 30, 0.001)
        c0, t0 = cpu_s(gs.pid), gi_seen[-1]
        wait_for(lambda: gis() > n0, 60, 0.005)
        t1, c1 = time.perf_counter(), cpu_s(gs.pid)
        print(f"iec104 GI {points} points: gridscada {1000 * (t1 - t0):.0f} ms, {1000 * (c1 - c0):.1f} ms CPU",
              flush=True)

        # The peer: c104's client, the same interrogation.
        cl = c104.Client(tick_rate_ms=50)
        conn = cl.add_connection(ip="127.0.0.1", port=port, init=c104.Init.MUTED)
        cst = conn.add_station(common_address=1)
        for i in range(1, points + 1):
            cst.add_point(io_address=i, type=c104.Type.M_ME_NC_1)
        done = []

        # The interrogation's ACT_TERM (type 100, cause 10), received.
        def on_term(connection: c104.Connection, data: bytes) -> None:
            if len(data) > 8 and data[6] == 100 and data[8] & 0x3F == 10:
                done.append(time.perf_counter())
        conn.on_receive_raw(callable=on_term)
        cl.start()
        wait_for(lambda: conn.is_connected, 20)
        conn.unmute()
        wait_for(lambda: conn.state == c104.ConnectionState.OPEN, 10)
        p0 = time.process_time()
        seen0 = len(gi_seen)
        conn.interrogation(common_address=1, wait_for_response=False)
        wait_for(lambda: done and len(gi_seen) > seen0, 60, 0.001)
        p1 = time.process_time()
        t0 = gi_seen[seen0]
        print(f"iec104 GI {points} points: c104 client {1000 * (done[0] - t0):.0f} ms, "
              f"{1000 * (p1 - p0):.0f} ms CPU (client and station share the process: an upper bound)",
              flush=True)
        cl.stop()

        # Spontaneous data at `rate` points/s for `seconds`.
        def stream():
            n, start = 0, time.perf_counter()
            end = start + seconds
            while time.perf_counter() < end:
                due = int((time.perf_counter() - start) * rate)
                while n < due:
                    p = pts[n % points]
                    p.value = float(n)
                    p.transmit(cause=c104.Cot.SPONTANEOUS)
                    n += 1
                time.sleep(0.001)
            return n
        # The peer takes the same stream at the same time, in a process
        # of its own.
        peer = subprocess.Popen([sys.executable, "-c", C104_CLIENT, str(port), str(points)],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1)

        def mark():
            peer.stdin.write("MARK\n")
            peer.stdin.flush()
            _, n, _, cpu = peer.stdout.readline().split()
            return int(n), float(cpu)
        ready = peer.stdout.readline().strip()
        if ready != "READY":
            print(f"iec104 spontaneous: c104's client did not start ({ready})", flush=True)
        events = lambda: metric(fetch(f"{base}/metrics"), "gridscada_iec104_events_total", "B") or 0
        ev0 = events()
        pn0, pc0 = mark()
        c0 = cpu_s(gs.pid)
        t0 = time.perf_counter()
        sent = stream()
        # Until both have everything, or neither took more for a second (a
        # station that feeds two connections may drop some from its queues).
        last, still = None, 0
        t1 = time.perf_counter()
        while time.perf_counter() - t0 < seconds + 30:
            now = (events() - ev0, mark()[0] - pn0)
            if now[0] >= sent and now[1] >= sent:
                t1 = time.perf_counter()
                break
            if now != last:
                last, still, t1 = now, 0, time.perf_counter()
            else:
                still += 1
                if still >= 5:
                    break
            time.sleep(0.2)
        c1 = cpu_s(gs.pid)
        pn1, pc1 = mark()
        got = events() - ev0
        print(f"iec104 spontaneous: {sent} points sent in {seconds} s ({sent / seconds:.0f}/s); gridscada took "
              f"{got:.0f}, {100 * (c1 - c0) / (t1 - t0):.1f} % of a core; c104's client took {pn1 - pn0}, "
              f"{100 * (pc1 - pc0) / (t1 - t0):.1f} % of a core", flush=True)
        peer.stdin.close()
        peer.wait(10)
    finally:
        gs.terminate()
        gs.wait(20)
        server.stop()


# --- 3: DNP3 integrity poll ------------------------------------------------

def dnp3(points=10_000):
    port = free_port()
    tags = [f'[[device]]\nname = "O"\nprotocol = "dnp3"\naddress = "127.0.0.1:{port}"\n'
            f'[device.dnp3]\noutstation_address = 10\nintegrity_period_s = 15\nunsolicited = false\n'
            f'event_poll_period_s = 0\n']
    for i in range(points):
        tags.append(f'[[tag]]\nname = "O.A{i}"\ndevice = "O"\ntype = "f32"\n'
                    f'dnp3 = {{ point = "analog_input", index = {i} }}\n')
    d, http = plant_dir("\n".join(tags))
    sim = subprocess.Popen([BIN, "sim", "--config", d], stdin=subprocess.PIPE,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    gs = None
    try:
        wait_for(lambda: port_open(port), 30, 0.2)
        # gridscada reaches the outstation through a relay that sees its polls.
        proxy = Proxy(port)
        with open(os.path.join(d, "tags.toml")) as f:
            through = f.read().replace(f"127.0.0.1:{port}", f"127.0.0.1:{proxy.port}", 1)
        with open(os.path.join(d, "tags.toml"), "w") as f:
            f.write(through)
        gs = demo(d, http, os.path.join(d, "data"), ["O"])
        proxy.pid = gs.pid
        base = f"http://127.0.0.1:{http}"
        polls = lambda: metric(fetch(f"{base}/metrics"), "gridscada_dnp3_integrity_polls_total", "O") or 0
        if not wait_for(lambda: polls() >= 1, 120, 0.2):
            print("dnp3: gridscada never finished its first integrity poll", flush=True)
            return
        # The periodic poll, in steady state: from the request on the wire
        # to gridscada's count of completed polls.
        n0, seen0 = polls(), len(proxy.polls)
        wait_for(lambda: len(proxy.polls) > seen0, 30, 0.001)
        t0, c0 = proxy.polls[-1]
        wait_for(lambda: polls() > n0, 60, 0.005)
        t1, c1 = time.perf_counter(), cpu_s(gs.pid)
        print(f"dnp3 integrity {points} points: gridscada {1000 * (t1 - t0):.0f} ms, {1000 * (c1 - c0):.1f} ms CPU",
              flush=True)
        gs.terminate()
        gs.wait(20)
        gs = None

        # The peer: dnp3py's master, the same integrity poll.
        asyncio.run(dnp3py_integrity(port, points))
    except Exception as e:
        print(f"dnp3: {e!r}", flush=True)
    finally:
        if gs is not None:
            gs.terminate()
            gs.wait(20)
        sim.terminate()
        sim.wait(20)


async def dnp3py_integrity(port, points):
    from dnp3.master import DefaultSOEHandler, Master, MasterConfig, MasterTcpRunner
    from dnp3.master.config import PollingConfig
    soe = DefaultSOEHandler()
    master = Master(config=MasterConfig(address=1, outstation_address=10,
                                        polling=PollingConfig(integrity_poll_interval=0)),
                    handler=soe)
    runner = MasterTcpRunner(master=master, host="127.0.0.1", port=port, response_timeout=60)
    await asyncio.wait_for(runner.open(), 10)
    try:
        await runner.integrity_poll()  # the first: the restart, warm-up
        p0, t0 = time.process_time(), time.perf_counter()
        infos = await runner.integrity_poll()
        t1, p1 = time.perf_counter(), time.process_time()
        print(f"dnp3 integrity {points} points: dnp3py master {1000 * (t1 - t0):.0f} ms, {1000 * (p1 - p0):.0f} ms CPU "
              f"({len(infos or [])} fragments)", flush=True)
    finally:
        await runner.close()


# --- 3b: DNP3 events at 2,000/s ---------------------------------------------

def event_source(port, points, rate):
    src = subprocess.Popen([EVENT_SOURCE, str(port), "--points", str(points), "--rate", str(rate),
                            "--outstation", "10"], stdout=subprocess.PIPE, text=True, bufsize=1)
    line = src.stdout.readline().strip()
    if line != "LISTENING":
        raise RuntimeError(f"the event source did not start: {line!r}")
    # Its "GENERATED" lines are not needed: drain them.
    threading.Thread(target=lambda: [None for _ in src.stdout], daemon=True).start()
    return src


def dnp3_events(rate=2_000, points=1_000, seconds=10, period=0.2):
    if not os.path.exists(EVENT_SOURCE):
        print(f"dnp3 events: no event source at {EVENT_SOURCE} (cargo build --release -p gridscada-dnp3 "
              f"--example dnp3_event_source)", flush=True)
        return
    for how, session in (("event polls every 0.2 s", f"event_poll_period_s = {period}\nunsolicited = false\n"),
                         ("unsolicited responses", "event_poll_period_s = 0\nunsolicited = true\n")):
        port = free_port()
        src = event_source(port, points, rate)
        tags = [f'[[device]]\nname = "O"\nprotocol = "dnp3"\naddress = "127.0.0.1:{port}"\n'
                f'[device.dnp3]\noutstation_address = 10\nintegrity_period_s = 3600\n{session}']
        for i in range(points):
            tags.append(f'[[tag]]\nname = "O.A{i}"\ndevice = "O"\ntype = "f32"\n'
                        f'dnp3 = {{ point = "analog_input", index = {i} }}\n')
        d, http = plant_dir("\n".join(tags))
        gs = demo(d, http, os.path.join(d, "data"), ["O"])
        base = f"http://127.0.0.1:{http}"
        try:
            polls = lambda: metric(fetch(f"{base}/metrics"), "gridscada_dnp3_integrity_polls_total", "O") or 0
            if not wait_for(lambda: polls() >= 1, 120, 0.2):
                print("dnp3 events: gridscada never finished its first integrity poll", flush=True)
                continue
            events = lambda: metric(fetch(f"{base}/metrics"), "gridscada_dnp3_events_total", "O") or 0
            overflows = lambda: metric(fetch(f"{base}/metrics"), "gridscada_dnp3_overflows_total", "O") or 0
            time.sleep(3)  # past the start
            e0, o0, c0, t0 = events(), overflows(), cpu_s(gs.pid), time.perf_counter()
            time.sleep(seconds)
            e1, o1, c1, t1 = events(), overflows(), cpu_s(gs.pid), time.perf_counter()
            print(f"dnp3 events at {rate}/s ({how}): gridscada took {(e1 - e0) / (t1 - t0):.0f} events/s, "
                  f"{100 * (c1 - c0) / (t1 - t0):.1f} % of a core, {o1 - o0:.0f} buffer overflows", flush=True)
        finally:
            gs.terminate()
            gs.wait(20)
            src.terminate()
            src.wait(10)

    # The peer: dnp3py's master, class polls at the same period.
    port = free_port()
    src = event_source(port, points, rate)
    try:
        asyncio.run(dnp3py_events(port, seconds, period, rate))
    except Exception as e:
        print(f"dnp3 events: dnp3py master failed: {e!r}", flush=True)
    finally:
        src.terminate()
        src.wait(10)


async def dnp3py_events(port, seconds, period, rate):
    from dnp3.master import DefaultSOEHandler, Master, MasterConfig, MasterTcpRunner
    from dnp3.master.config import PollingConfig

    class Counting(DefaultSOEHandler):
        n = 0

        def on_analog_input(self, values, info):
            Counting.n += len(values)
            super().on_analog_input(values, info)
    master = Master(config=MasterConfig(address=1, outstation_address=10,
                                        polling=PollingConfig(integrity_poll_interval=0)),
                    handler=Counting())
    runner = MasterTcpRunner(master=master, host="127.0.0.1", port=port, response_timeout=10)
    await asyncio.wait_for(runner.open(), 10)
    try:
        await runner.integrity_poll()

        async def polls(until):
            while time.perf_counter() < until:
                started = time.perf_counter()
                await runner.class_poll()
                await asyncio.sleep(max(0.0, period - (time.perf_counter() - started)))
        await polls(time.perf_counter() + 3)  # past the start
        n0, p0, t0 = Counting.n, time.process_time(), time.perf_counter()
        await polls(t0 + seconds)
        n1, p1, t1 = Counting.n, time.process_time(), time.perf_counter()
        print(f"dnp3 events at {rate}/s (class polls every {period} s): dnp3py master took "
              f"{(n1 - n0) / (t1 - t0):.0f} events/s, {100 * (p1 - p0) / (t1 - t0):.1f} % of a core", flush=True)
    finally:
        await runner.close()


# --- 4: 50 stations --------------------------------------------------------

def stations(n=50, per=2_000, seconds=30):
    ports = [free_port() for _ in range(n)]
    tags = []
    for s, port in enumerate(ports):
        tags.append(f'[[device]]\nname = "S{s}"\nprotocol = "iec104"\naddress = "127.0.0.1:{port}"\n'
                    f'[device.iec104]\ncommon_address = {s + 1}\n')
        for i in range(1, per + 1):
            tags.append(f'[[tag]]\nname = "S{s}.M{i}"\ndevice = "S{s}"\ntype = "f32"\n'
                        f'iec104 = {{ ioa = {i}, point = "M_ME_NC" }}\n')
    d, http = plant_dir("\n".join(tags))
    sim = subprocess.Popen([BIN, "sim", "--config", d], stdin=subprocess.PIPE,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    gs = None
    try:
        wait_for(lambda: all(port_open(p) for p in ports), 60, 0.5)
        data = os.path.join(d, "data")
        gs = demo(d, http, data, [f"S{s}" for s in range(n)])
        base = f"http://127.0.0.1:{http}"
        t0 = time.perf_counter()
        done = lambda: all((metric(txt, "gridscada_iec104_interrogations_total", f"S{s}") or 0) >= 1
                           for txt in [fetch(f"{base}/metrics")] for s in range(n))
        if not wait_for(done, 180, 0.2):
            print("stations: not every station was interrogated in 180 s", flush=True)
            return
        t1 = time.perf_counter()
        # The start's tail (the first samples of every tag through the
        # historian and the subscribers), then the steady state.
        settle = 45
        c0 = cpu_s(gs.pid)
        time.sleep(settle)
        c1 = cpu_s(gs.pid)
        time.sleep(seconds)
        c2 = cpu_s(gs.pid)
        print(f"iec104 {n} stations x {per} points: all interrogated {t1 - t0:.1f} s after start; "
              f"{100 * (c1 - c0) / settle:.0f} % of a core over the next {settle} s; then "
              f"{100 * (c2 - c1) / seconds:.1f} % of a core over {seconds} s (static values), "
              f"RSS {rss_mib(gs.pid):.0f} MiB (gridscada demo; the stations in a separate sim process)",
              flush=True)
    finally:
        if gs is not None:
            gs.terminate()
            gs.wait(20)
        sim.terminate()
        sim.wait(20)


if __name__ == "__main__":
    which = sys.argv[1:] or ["iec104", "dnp3", "events", "stations"]
    if "iec104" in which:
        iec104()
    if "dnp3" in which:
        dnp3()
    if "events" in which:
        dnp3_events()
    if "stations" in which:
        stations()
