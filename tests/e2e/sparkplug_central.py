#!/usr/bin/env python3
"""gridscada as the central Sparkplug B host, against Debian's mosquitto and
three simulated edge nodes (sparkplug_edge_sim.py, paho-mqtt + protobuf).
Run by sparkplug_central.sh, which starts nothing itself but this.

Checks: the central /api/tags shows all three sites from their births;
STATE online is retained with its timestamp; killing one edge (-9, its will
NDEATH) turns its tags Bad within the keep-alive and only its tags;
restarting it brings them back through a rebirth; a write from the central
API reaches the right edge as a DCMD and answers only after that edge's DDATA
reports the value (and is audited); an edge that never reports times out
with 504; malformed, unknown-alias and oversized messages are counted and
change nothing; an orderly stop publishes STATE offline.

Prints "N passed, M failed" last; exits non-zero on any failure.
"""

import http.cookiejar
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request

import paho.mqtt.client as mqtt

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
BIN = os.environ.get("GRIDSCADA_BIN") or os.path.join(
    os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target")), "debug", "gridscada")
MOSQUITTO = os.environ.get("MOSQUITTO", "/usr/sbin/mosquitto")
SIM = os.path.join(HERE, "sparkplug_edge_sim.py")
KEEPALIVE = 2  # the edges' MQTT keep-alive, s: the broker sends the will after 1.5x
SITES = ["site-a", "site-b", "site-c"]
GROUP = "Grid"

passed = failed = 0
procs = []


def ok(msg):
    global passed
    passed += 1
    print(f"ok   {msg}", flush=True)


def bad(msg):
    global failed
    failed += 1
    print(f"FAIL {msg}", flush=True)


def check(cond, msg, detail=""):
    ok(msg) if cond else bad(f"{msg}{': ' + str(detail) if detail else ''}")
    return cond


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def wait_for(what, timeout, step=0.1):
    """Polls `what()` until truthy; returns (value, seconds) or (None, timeout)."""
    start = time.monotonic()
    while time.monotonic() - start < timeout:
        v = what()
        if v:
            return v, time.monotonic() - start
        time.sleep(step)
    return None, timeout


def start(args, log):
    p = subprocess.Popen(args, stdout=open(log, "w"), stderr=subprocess.STDOUT)
    procs.append(p)
    return p


class Api:
    def __init__(self, base):
        self.base = base
        self.opener = urllib.request.build_opener(
            urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))

    def call(self, method, path, body=None):
        data = json.dumps(body).encode() if body is not None else None
        req = urllib.request.Request(self.base + path, data=data, method=method, headers={
            "Content-Type": "application/json", "Origin": self.base})
        try:
            with self.opener.open(req, timeout=30) as r:
                return r.status, json.loads(r.read() or b"null")
        except urllib.error.HTTPError as e:
            return e.code, json.loads(e.read() or b"null")

    def tags(self):
        status, body = self.call("GET", "/api/tags")
        return {t["name"]: t for t in body["tags"]} if status == 200 else {}

    def metrics(self):
        req = urllib.request.Request(self.base + "/metrics")
        with self.opener.open(req, timeout=10) as r:
            text = r.read().decode()
        out = {}
        for line in text.splitlines():
            if line.startswith("gridscada_sparkplug_host") and " " in line:
                k, v = line.rsplit(" ", 1)
                out[k] = float(v)
        return out


def login(base, data, start_timeout=60, health_timeout=30):
    """Waits for a `demo` server's credentials and /healthz, then logs in as
    its administrator: (Api, None), or (None, why: "no credentials",
    "no healthz", or the login's HTTP status)."""
    creds = os.path.join(data, "credentials.txt")
    if not wait_for(lambda: os.path.exists(creds) and os.path.getsize(creds) > 0, start_timeout)[0]:
        return None, "no credentials"

    def healthy():
        try:
            with urllib.request.urlopen(base + "/healthz", timeout=2) as r:
                return r.status == 200
        except (OSError, urllib.error.URLError):
            return False
    if not wait_for(healthy, health_timeout, 0.2)[0]:
        return None, "no healthz"
    user, password = next(l.split()[1:3] for l in open(creds) if l.startswith("administrator"))
    api = Api(base)
    status, _ = api.call("POST", "/api/session", {"username": user, "password": password})
    return (api, None) if status == 200 else (None, status)


def site_alarm(api, node):
    """(status, [the system alarm of `node`]) from /api/alarms."""
    status, body = api.call("GET", "/api/alarms")
    rows = body.get("alarms", []) if isinstance(body, dict) else (body or [])
    return status, [a for a in rows if a.get("key") == f"sparkplug:{node}"]


def retained_state(port, host_id, timeout=5):
    """The retained STATE of the host, read by a fresh MQTT client."""
    got = []
    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"state-reader-{time.time()}")
    c.on_message = lambda _c, _u, m: got.append((m.retain, m.qos, json.loads(m.payload)))
    c.on_connect = lambda cl, *_: cl.subscribe(f"spBv1.0/STATE/{host_id}", qos=1)
    c.connect("127.0.0.1", port)
    c.loop_start()
    wait_for(lambda: got, timeout)
    c.loop_stop()
    c.disconnect()
    return got[0] if got else None


def sim(i, node, port, tmp, *extra, bdseq=0):
    return start([sys.executable, SIM, "run", "--broker", f"127.0.0.1:{port}", "--group", GROUP,
                  "--node", node, "--index", str(i), "--keepalive", str(KEEPALIVE),
                  "--bdseq", str(bdseq), *extra],
                 os.path.join(tmp, f"{node}-{bdseq}.log"))


def commands(tmp, node, bdseq=0):
    path = os.path.join(tmp, f"{node}-{bdseq}.log")
    out = []
    for line in open(path):
        try:
            e = json.loads(line)
        except ValueError:
            continue
        if e.get("event") == "DCMD":
            out.append(e)
    return out


def main(tmp):
    mport, hport = free_port(), free_port()
    base = f"http://127.0.0.1:{hport}"
    with open(os.path.join(tmp, "mosquitto.conf"), "w") as f:
        f.write(f"listener {mport} 127.0.0.1\nallow_anonymous true\npersistence false\n")
    start([MOSQUITTO, "-c", os.path.join(tmp, "mosquitto.conf")], os.path.join(tmp, "mosquitto.log"))
    time.sleep(0.5)

    conf = os.path.join(tmp, "central")
    os.makedirs(conf)
    # A central host with no tag files and no devices of its own.
    with open(os.path.join(conf, "gridscada.toml"), "w") as f:
        f.write(f"""[mqtt]
broker = "mqtt://127.0.0.1:{mport}"
group = "{GROUP}"

[mqtt.host]
host_id = "central"
max_message_bytes = 1048576
write_timeout_s = 3
rebirth_interval_s = 1
""")
    check(subprocess.run([BIN, "check", conf], capture_output=True).returncode == 0,
          "gridscada check takes a central host without tag files")
    data = os.path.join(tmp, "data")
    server = start([BIN, "demo", "--config", conf, "--http", f"127.0.0.1:{hport}", "--data", data],
                   os.path.join(tmp, "central.log"))
    api, why = login(base, data)
    if why == "no credentials":
        bad("the central server never started (central.log)")
        return
    if why == "no healthz":
        bad("the central server never answered /healthz (central.log)")
        return
    if not check(api is not None, "log in to the central server", why):
        return

    state = retained_state(mport, "central")
    check(state is not None and state[0] and state[1] == 1 and state[2].get("online") is True
          and isinstance(state[2].get("timestamp"), int),
          "STATE/central is retained, QoS 1, online with a timestamp", state)

    # Site a never confirms writes (for the timeout); site c confirms late.
    sim(0, "site-a", mport, tmp, "--ignore-writes")
    sim(1, "site-b", mport, tmp)
    sim(2, "site-c", mport, tmp, "--confirm-delay", "1.5")

    want = [f"{s}.{m}" for s in SITES for m in ("Feeder.Volts", "P", "P_set", "Running")]
    tags, secs = wait_for(lambda: (lambda t: t if all(
        n in t and t[n]["quality"]["code"] == "good" for n in want) else None)(api.tags()), 20)
    if not check(tags is not None, "central /api/tags shows the tags of all three sites, Good",
                 sorted(api.tags())):
        return
    check(all(tags[f"{s}.Feeder.Volts"]["value"] == 230.0 + i for i, s in enumerate(SITES))
          and tags["site-a.Feeder.Volts"]["units"] == "V",
          "each site's values and units come from its own birth")
    check(tags["site-b.P_set"]["writable"] and tags["site-b.P_set"]["write_role"] == "operator"
          and not tags["site-b.Running"]["writable"],
          "writability comes from the birth, the role from [mqtt.host] write_role")
    m = api.metrics()
    check(m.get("gridscada_sparkplug_host_sites_online") == 3, "/metrics: 3 sites online",
          m.get("gridscada_sparkplug_host_sites_online"))

    # --- Killing one edge: its will (NDEATH) -----------------------------------
    victim = procs[-2]  # site-b
    victim.send_signal(signal.SIGKILL)
    victim.wait()
    t0 = time.monotonic()
    dead, secs = wait_for(lambda: (lambda t: t if all(
        t[f"site-b.{x}"]["quality"].get("reason") == "site offline"
        for x in ("Feeder.Volts", "P", "P_set", "Running")) else None)(api.tags()), 10)
    check(dead is not None and secs <= 1.5 * KEEPALIVE + 2,
          f"kill -9 of site-b: its tags are Bad 'site offline' within the keep-alive ({secs:.1f} s)")
    if dead:
        check(all(dead[f"{s}.P"]["quality"]["code"] == "good" for s in ("site-a", "site-c")),
              "the other sites stay Good")
    active = wait_for(lambda: (lambda a: a and a[0]["active"])(site_alarm(api, "site-b")[1]), 5)[0]
    check(active, "the system alarm sparkplug:site-b stands while it is dead")
    status, body = api.call("POST", "/api/tags/site-b.P_set/write", {"value": 12})
    check(status == 502 and "site offline" in body.get("detail", ""),
          "a write to the dead site is refused with its reason", (status, body))

    reborn = sim(1, "site-b", mport, tmp, bdseq=1)
    back, secs = wait_for(lambda: (lambda t: t if all(
        t[f"site-b.{x}"]["quality"]["code"] == "good"
        for x in ("Feeder.Volts", "P", "P_set", "Running")) else None)(api.tags()), 15)
    check(back is not None, f"restarting site-b brings its tags back Good through its birth ({secs:.1f} s)")
    check(api.metrics().get("gridscada_sparkplug_host_sites_online") == 3, "3 sites online again")

    def site_b_events():
        status, events = api.call("GET", "/api/events?type=sparkplug")
        text = json.dumps(events)
        return status == 200 and "site-b died (NDEATH)" in text and "site-b born (NBIRTH)" in text
    check(wait_for(site_b_events, 5)[0], "the event log records site-b's death and birth")
    status, standing = site_alarm(api, "site-b")
    check(status == 200 and standing and not standing[0]["active"] and standing[0]["selection"] == "site-b",
          "its system alarm sparkplug:site-b was raised and has returned to normal", (status, standing))

    # A frozen edge keeps its socket open: only the broker's keep-alive
    # finds it out (mosquitto 2.0 checks it coarsely, so its will comes
    # some seconds after 1.5 keep-alives). The host must act on the will
    # at once.
    deaths = []
    watcher = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="ndeath-watcher")
    watcher.on_message = lambda *_: deaths.append(time.monotonic())
    watcher.on_connect = lambda cl, *_: cl.subscribe(f"spBv1.0/{GROUP}/NDEATH/site-b", qos=1)
    watcher.connect("127.0.0.1", mport)
    watcher.loop_start()
    time.sleep(0.5)
    frozen_at = time.monotonic()
    reborn.send_signal(signal.SIGSTOP)
    frozen, _ = wait_for(
        lambda: api.tags()["site-b.P"]["quality"].get("reason") == "site offline" and time.monotonic(),
        30, 0.05)
    watcher.loop_stop()
    watcher.disconnect()
    if check(frozen and deaths, "a frozen site-b (SIGSTOP): the broker sends its will NDEATH"):
        check(frozen - deaths[0] <= 1.0,
              f"its tags are Bad {frozen - deaths[0]:.2f} s after the will "
              f"(the broker took {deaths[0] - frozen_at:.1f} s with a {KEEPALIVE} s keep-alive)")
    reborn.send_signal(signal.SIGCONT)
    thawed, secs = wait_for(lambda: api.tags()["site-b.P"]["quality"]["code"] == "good", 20)
    check(thawed, f"thawed, it reconnects and is Good again through its birth ({secs:.1f} s)")

    # --- Writes ---------------------------------------------------------------
    t0 = time.monotonic()
    status, body = api.call("POST", "/api/tags/site-c.P_set/write", {"value": 33.25})
    took = time.monotonic() - t0
    check(status == 200 and body["value"] == 33.25 and body["quality"]["code"] == "good",
          "a write to site-c.P_set answers with the confirmed value", (status, body))
    check(took >= 1.4, f"it answered only after the edge's DDATA ({took:.2f} s, the edge waits 1.5 s)")
    c_cmds = commands(tmp, "site-c")
    check(len(c_cmds) == 1 and c_cmds[0]["topic"] == f"spBv1.0/{GROUP}/DCMD/site-c/PV1"
          and c_cmds[0]["value"] == 33.25 and c_cmds[0]["name"] == "P_set",
          "site-c received it as a DCMD to PV1/P_set", c_cmds)
    check(not commands(tmp, "site-a") and not commands(tmp, "site-b", 1),
          "no other site received a command")
    status, events = api.call("GET", "/api/events?type=write")
    rows = events if isinstance(events, list) else (events or {}).get("events", [])
    texts = json.dumps(rows)
    check(status == 200 and "site-c.P_set" in texts and "confirmed 33.25" in texts,
          "the write is audited (request and confirmation in the event log)", (status, texts[:400]))

    t0 = time.monotonic()
    status, body = api.call("POST", "/api/tags/site-a.P_set/write", {"value": 7})
    took = time.monotonic() - t0
    check(status == 504 and 2.5 <= took <= 6,
          f"a write the edge never confirms times out with 504 after write_timeout_s ({took:.1f} s)",
          (status, body))
    check(api.tags()["site-a.P_set"]["value"] == 50.0,
          "and the central value stays the edge's last report")
    status, body = api.call("POST", "/api/tags/site-a.Running/write", {"value": False})
    check(status == 403, "a tag its birth does not mark writable is read-only", (status, body))

    # --- Bad input --------------------------------------------------------------
    before = api.tags()
    m0 = api.metrics()
    subprocess.run([sys.executable, SIM, "bad", "--broker", f"127.0.0.1:{mport}", "--group", GROUP,
                    "--node", "site-c", "--seq", "77", "--oversize", str(2 * 1024 * 1024)],
                   check=False, timeout=30)

    def counted():
        m = api.metrics()
        r = lambda k: m.get(f'gridscada_sparkplug_host_refused_total{{reason="{k}"}}', 0) \
            - m0.get(f'gridscada_sparkplug_host_refused_total{{reason="{k}"}}', 0)
        return m if all(r(k) >= 1 for k in ("malformed", "unknown_alias", "oversized")) else None
    m1, _ = wait_for(counted, 10)
    check(m1 is not None, "malformed, unknown-alias and oversized messages are counted")
    after = api.tags()
    check(server.poll() is None and set(after) == set(before)
          and after["site-c.P_set"]["value"] == 33.25,
          "they change nothing and the server runs on")
    check((m1 or {}).get("gridscada_sparkplug_host_rebirth_requests_total", 0) >= 1,
          "the unknown alias asked site-c for a rebirth")
    check((m1 or {}).get("gridscada_sparkplug_host_bytes_total", 0) > 2 * 1024 * 1024
          and (m1 or {}).get('gridscada_sparkplug_host_messages_total{type="DDATA"}', 0) > 0,
          "/metrics counts messages and bytes")

    # --- Orderly stop: STATE offline ------------------------------------------
    server.send_signal(signal.SIGTERM)
    try:
        server.wait(timeout=20)
    except subprocess.TimeoutExpired:
        bad("the central server did not stop within 20 s")
    state2 = retained_state(mport, "central")
    check(state2 is not None and state2[2].get("online") is False
          and state and state2[2].get("timestamp") == state[2].get("timestamp"),
          "an orderly stop leaves STATE offline, with the birth's timestamp", state2)


if __name__ == "__main__":
    tmp = tempfile.mkdtemp(prefix="sparkplug-central-")
    try:
        main(tmp)
    except Exception as e:  # a crash of the test is a failure, with its cause
        import traceback
        traceback.print_exc()
        bad(f"the test stopped: {e}")
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()
        if failed:
            print(f"logs kept in {tmp}")
            for name in ("central.log",):
                path = os.path.join(tmp, name)
                if os.path.exists(path):
                    print(f"--- {name} (last 30 lines)")
                    print("".join(open(path).readlines()[-30:]))
        else:
            import shutil
            shutil.rmtree(tmp, ignore_errors=True)
    print(f"{passed} passed, {failed} failed")
    sys.exit(1 if failed else 0)
