#!/usr/bin/env python3
"""The primary host's STATE (Sparkplug 3.0), end to end, on Debian's mosquitto.
Run by sparkplug_primary.sh (the setup of sparkplug_central.sh).

Edge: gridscada `demo --mqtt URL --mqtt-primary-host scada` and a Python
primary host (paho-mqtt + protobuf) that owns `spBv1.0/STATE/scada`:
- the host's retained STATE says offline: the edge connects but publishes no
  NBIRTH and buffers its samples;
- an online STATE older than the last one is ignored (still no NBIRTH);
- online with a newer timestamp: NBIRTH, DBIRTHs, then the buffered samples
  as historical data; a counter tag that changes every scan has no gap;
- the host's death (its will: offline, its birth's timestamp): the edge sends
  NDEATH (that birth's bdSeq) and buffers again; a late will of an older host
  session, sent while the edge publishes, ends nothing;
- online again: a new birth, and the offline window arrives as history.
Central host: gridscada `[mqtt.host]`; after a broker restart its STATE
carries a newer timestamp, and its will (kill -9) carries that one.

Prints "N passed, M failed" last; exits non-zero on any failure.
"""

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

import paho.mqtt.client as mqtt

import sparkplug_central as c  # the process, HTTP and wait helpers
from sparkplug_edge_sim import Payload  # the Tahu payload, declared through protobuf

GROUP = "gridscada"  # the group `demo --mqtt` publishes under
HOST_ID = "scada"
check = c.check


class PrimaryHost:
    """Publishes its STATE and records what the edge sends."""

    def __init__(self, port):
        self.lock = threading.Lock()
        self.messages = []  # (arrival ms, kind, payload)
        self.births = {}  # device -> {alias: name}
        self.history = {}  # tag name -> [(ts, value, historical)]
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="primary-host")
        self.client.on_message = self.on_message
        self.client.on_connect = lambda cl, *_: cl.subscribe(f"spBv1.0/{GROUP}/#", qos=1)
        self.client.connect("127.0.0.1", port, keepalive=5)
        self.client.loop_start()

    def state(self, online, timestamp):
        body = json.dumps({"online": online, "timestamp": timestamp})
        self.client.publish(f"spBv1.0/STATE/{HOST_ID}", body, qos=1, retain=True).wait_for_publish(5)

    def on_message(self, _c, _u, msg):
        parts = msg.topic.split("/")
        kind, device = parts[2], (parts[4] if len(parts) > 4 else None)
        if kind in ("NCMD", "DCMD"):
            return
        p = Payload()
        p.ParseFromString(msg.payload)
        with self.lock:
            self.messages.append((int(time.time() * 1000), kind, p))
            if kind == "DBIRTH":
                self.births[device] = {m.alias: m.name for m in p.metrics}
                for m in p.metrics:
                    self.record(m.name, m, False)
            elif kind == "DDATA":
                names = self.births.get(device, {})
                for m in p.metrics:
                    if m.alias in names:
                        self.record(names[m.alias], m, m.is_historical)

    def record(self, name, m, historical):
        kind = m.WhichOneof("value")
        if kind:
            self.history.setdefault(name, []).append((m.timestamp, getattr(m, kind), historical))

    def count(self, kind):
        with self.lock:
            return sum(1 for _, k, _ in self.messages if k == kind)

    def bd_seqs(self, kind):
        with self.lock:
            return [next((m.long_value for m in p.metrics if m.name == "bdSeq"), None)
                    for _, k, p in self.messages if k == kind]


def edge_metrics(api):
    out = {}
    try:
        with api.opener.open(api.base + "/metrics", timeout=10) as r:
            for line in r.read().decode().splitlines():
                if line.startswith("gridscada_mqtt_") and " " in line:
                    k, v = line.rsplit(" ", 1)
                    out[k] = float(v)
    except OSError:
        pass
    return out


def no_gap(samples, what):
    """A counter's distinct values over a window step by about one scan."""
    values = sorted({v for _, v, _ in samples})
    steps = [b - a for a, b in zip(values, values[1:])]
    big = [s for s in steps if s > 4 * max(1, min(steps or [1]))]
    check(len(values) > 5 and not big,
          f"{what}: no gap ({len(values)} values, steps {min(steps or [0])}..{max(steps or [0])})",
          f"big steps {big[:5]}")


def edge(tmp, mport):
    host = PrimaryHost(mport)
    t0 = int(time.time() * 1000) - 60_000
    # The primary host was there and is gone: its will, retained.
    host.state(False, t0)

    hport = c.free_port()
    base, data = f"http://127.0.0.1:{hport}", os.path.join(tmp, "edge-data")
    server = c.start([c.BIN, "demo", "--http", f"127.0.0.1:{hport}", "--data", data,
                      "--mqtt", f"mqtt://127.0.0.1:{mport}", "--mqtt-primary-host", HOST_ID],
                     os.path.join(tmp, "edge.log"))
    api, why = c.login(base, data, 90, 60)
    if not check(api is not None, "log in to the edge server", why):
        return
    counter = next((n for n in sorted(api.tags()) if n.endswith(".Comm.Requests")), None)
    if not check(counter is not None, "a counter tag to follow (*.Comm.Requests)"):
        return

    connected, _ = c.wait_for(lambda: edge_metrics(api).get("gridscada_mqtt_connected") == 1, 30, 0.2)
    check(connected, "the edge connects to the broker")
    buffering, _ = c.wait_for(lambda: edge_metrics(api).get("gridscada_mqtt_buffered_samples", 0) > 0, 10, 0.2)
    # An online STATE older than the last one: ignored.
    host.state(True, t0 - 1000)
    time.sleep(2)
    check(host.count("NBIRTH") == 0 and host.count("DDATA") == 0,
          "primary host offline (and an older online STATE): no NBIRTH, no data",
          f"{host.count('NBIRTH')} NBIRTH, {host.count('DDATA')} DDATA")
    check(buffering, "primary host offline: the edge buffers its samples", edge_metrics(api))
    check(edge_metrics(api).get("gridscada_mqtt_primary_host_online") == 0,
          "/metrics: gridscada_mqtt_primary_host_online 0")

    # Online, a newer session of the host: births, then the buffer.
    t1 = int(time.time() * 1000)
    host.state(True, t1)
    born, secs = c.wait_for(lambda: host.count("NBIRTH") == 1 and host.count("DBIRTH") > 0, 15)
    check(born, f"primary host online (newer timestamp): NBIRTH and DBIRTHs ({secs:.1f} s)")
    drained, _ = c.wait_for(lambda: edge_metrics(api).get("gridscada_mqtt_buffered_samples", 1) == 0, 15, 0.2)
    time.sleep(1.5)
    m = edge_metrics(api)
    check(drained and m.get("gridscada_mqtt_replayed_samples_total", 0) > 0
          and m.get("gridscada_mqtt_dropped_samples_total", 1) == 0,
          "the buffered samples are sent, none dropped", m)
    check(m.get("gridscada_mqtt_primary_host_online") == 1, "/metrics: gridscada_mqtt_primary_host_online 1", m)
    with host.lock:
        seen = sorted(host.history.get(counter, []))
    historical = [s for s in seen if s[2] and s[0] < t1]
    check(len(historical) > 5, f"{counter}: the samples from before the host came online arrive as historical",
          f"{len(historical)} historical of {len(seen)}")
    no_gap(seen, f"{counter} from the edge's start to now")

    # A late will of an older host session while the edge publishes: ignored.
    n = host.count("DDATA")
    host.state(False, t1 - 1)
    time.sleep(1.5)
    check(host.count("NDEATH") == 0 and host.count("DDATA") > n,
          "an offline STATE older than the host's birth ends nothing")

    # The host dies (its will: offline with its birth's timestamp).
    off_at = int(time.time() * 1000)
    host.state(False, t1)
    died, _ = c.wait_for(lambda: host.count("NDEATH") == 1, 10)
    check(died and host.bd_seqs("NDEATH") == host.bd_seqs("NBIRTH")[:1],
          "primary host offline: the edge sends NDEATH with its birth's bdSeq",
          (host.bd_seqs("NBIRTH"), host.bd_seqs("NDEATH")))
    time.sleep(3)
    check(host.count("NBIRTH") == 1, "offline again: no new birth while the host is offline")
    m = edge_metrics(api)
    check(m.get("gridscada_mqtt_buffered_samples", 0) > 0 and m.get("gridscada_mqtt_primary_host_online") == 0,
          "offline again: the edge buffers", m)

    # Back: a new birth, and the offline window as history.
    on_at = int(time.time() * 1000)
    host.state(True, on_at)
    reborn, _ = c.wait_for(lambda: host.count("NBIRTH") == 2, 15)
    births = host.bd_seqs("NBIRTH")
    check(reborn and len(set(births)) == 2, "online again: a new NBIRTH with a new bdSeq", births)
    c.wait_for(lambda: edge_metrics(api).get("gridscada_mqtt_buffered_samples", 1) == 0, 15, 0.2)
    time.sleep(1.5)
    with host.lock:
        seen = sorted(host.history.get(counter, []))
    window = [s for s in seen if off_at <= s[0] <= on_at]
    historical = [s for s in window if s[2]]
    check(len(historical) > 0 and len(historical) >= 0.9 * len(window),
          f"{counter}: the samples of the offline window arrive as historical data",
          f"{len(historical)} of {len(window)}")
    no_gap([s for s in seen if s[0] >= t1 - 1000], f"{counter} across the host's death and return")

    server.send_signal(signal.SIGTERM)
    try:
        server.wait(timeout=20)
    except subprocess.TimeoutExpired:
        c.bad("the edge server did not stop within 20 s")
    host.client.loop_stop()
    host.client.disconnect()


def central(tmp, mport, conf_path):
    conf = os.path.join(tmp, "central")
    os.makedirs(conf)
    with open(os.path.join(conf, "gridscada.toml"), "w") as f:
        f.write(f'[mqtt]\nbroker = "mqtt://127.0.0.1:{mport}"\ngroup = "Grid"\n\n[mqtt.host]\nhost_id = "central"\n')
    hport = c.free_port()
    data = os.path.join(tmp, "central-data")
    server = c.start([c.BIN, "demo", "--config", conf, "--http", f"127.0.0.1:{hport}", "--data", data],
                     os.path.join(tmp, "central.log"))

    def state():
        s = c.retained_state(mport, "central", 1)
        return s and s[2]
    first, _ = c.wait_for(lambda: (lambda s: s if s and s.get("online") else None)(state()), 60, 0.5)
    if not check(first is not None, "the central host publishes STATE online"):
        return None
    # The broker restarts and forgets everything: a new host session.
    broker = restart_broker(conf_path, mport)
    second, _ = c.wait_for(lambda: (lambda s: s if s and s.get("online") else None)(state()), 20, 0.5)
    check(second is not None and second["timestamp"] > first["timestamp"],
          "after a broker restart the central host's STATE has a newer timestamp", (first, second))
    # Its will (kill -9) carries that session's timestamp.
    server.send_signal(signal.SIGKILL)
    server.wait(timeout=10)
    will, _ = c.wait_for(lambda: (lambda s: s if s and s.get("online") is False else None)(state()), 10, 0.5)
    check(will is not None and second is not None and will["timestamp"] == second["timestamp"],
          "the central host's will carries its current session's timestamp", (second, will))
    return broker


def restart_broker(conf_path, port):
    for p in c.procs:
        if p.args[0] == c.MOSQUITTO and p.poll() is None:
            p.kill()
            p.wait(5)
    return start_broker(conf_path, port)


def start_broker(conf_path, port):
    p = c.start([c.MOSQUITTO, "-c", conf_path], os.path.join(tmp_dir, f"mosquitto-{time.time():.0f}.log"))
    c.wait_for(lambda: port_open(port), 10, 0.05)
    return p


def port_open(port):
    try:
        socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
        return True
    except OSError:
        return False


def main(tmp):
    mport = c.free_port()
    conf_path = os.path.join(tmp, "mosquitto.conf")
    with open(conf_path, "w") as f:
        f.write(f"listener {mport} 127.0.0.1\nallow_anonymous true\npersistence false\n")
    start_broker(conf_path, mport)
    edge(tmp, mport)
    central(tmp, mport, conf_path)


if __name__ == "__main__":
    tmp_dir = tempfile.mkdtemp(prefix="sparkplug-primary-")
    try:
        main(tmp_dir)
    except Exception as e:  # a crash of the test is a failure, with its cause
        import traceback
        traceback.print_exc()
        c.bad(f"the test stopped: {e}")
    finally:
        for p in c.procs:
            if p.poll() is None:
                p.terminate()
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()
        if c.failed:
            print(f"logs kept in {tmp_dir}")
            for name in ("edge.log", "central.log"):
                path = os.path.join(tmp_dir, name)
                if os.path.exists(path):
                    print(f"--- {name} (last 30 lines)")
                    print("".join(open(path).readlines()[-30:]))
        else:
            shutil.rmtree(tmp_dir, ignore_errors=True)
    print(f"{c.passed} passed, {c.failed} failed")
    sys.exit(1 if c.failed else 0)
