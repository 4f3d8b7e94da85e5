#!/usr/bin/env python3
"""An independent Sparkplug B host for gridscada's edge node (tests/e2e/sparkplug_edge.sh).

It owns the broker (Debian's mosquitto, on the port it is given), subscribes
to the group with paho-mqtt, and decodes every message with the Eclipse Tahu
payload declared through protobuf's descriptors (sparkplug_edge_sim.Payload). It checks:

- births: NBIRTH with bdSeq and Node Control/Rebirth, a DBIRTH per device,
  every metric with name, alias, datatype, quality; seq 0 at NBIRTH then +1
  (mod 256) per message; DDATA by alias only;
- values: every tag of /api/tags was published with the same value, quality
  and timestamp;
- commands: a DCMD writes a simulated device's coil (confirmed by /api/tags
  and the event log); DCMDs to read-only, unknown, not-allowed tags,
  malformed and oversized payloads change nothing and are counted; a DCMD
  closing a zone MCB with a "Do not close" safety tag is refused with the
  tag's words and nothing goes out;
- outage: the broker is killed for OUTAGE seconds and restarted; the edge
  comes back with a new bdSeq, and every change of a tag that changes every
  scan is there as historical data, without a gap;
- NDEATH as the will, after the broker came back (gridscada stopped by the
  shell script is not checked here).

Prints "ok"/"FAIL" lines and "N passed, M failed" last.
"""

import argparse
import http.cookiejar
import json
import socket
import subprocess
import threading
import time
import urllib.error
import urllib.request

import paho.mqtt.client as mqtt
from sparkplug_edge_sim import Payload  # the Tahu payload, declared through protobuf

passed = 0
failed = 0


def check(what, cond, detail=""):
    global passed, failed
    if cond:
        passed += 1
        print(f"ok   {what}", flush=True)
    else:
        failed += 1
        print(f"FAIL {what}: {detail}", flush=True)


def metric_value(m):
    """A decoded metric's value as Python sees a tag value."""
    kind = m.WhichOneof("value")
    if m.is_null or kind is None:
        return None
    v = getattr(m, kind)
    dt = m.datatype
    if kind == "int_value":
        # Int8/16/32 are two's complement in a uint32.
        bits = {1: 8, 2: 16, 3: 32}.get(dt)
        if bits and v >= 1 << (bits - 1):
            v -= 1 << bits
    if kind == "long_value" and dt == 4 and v >= 1 << 63:
        v -= 1 << 64
    return v


def props(m):
    out = {}
    for k, pv in zip(m.properties.keys, m.properties.values):
        kind = pv.WhichOneof("value")
        out[k] = getattr(pv, kind) if kind else None
    return out


class Host:
    def __init__(self, port, group, node):
        self.group, self.node = group, node
        self.lock = threading.Lock()
        self.messages = []  # (arrival, kind, device, payload)
        self.births = {}  # device -> {alias: (name, datatype)}
        self.history = {}  # tag name -> list of (ts, value, quality, historical)
        self.seq_errors = []
        self.last_seq = None
        # DDATA of a session whose birth went out before this host subscribed.
        self.before_first_birth = 0
        self.bd_seq = None
        self.ndeaths = []
        self.client = mqtt.Client(client_id="sparkplug-test-host", clean_session=True)
        self.client.on_message = self.on_message
        self.client.on_connect = lambda c, u, f, rc: c.subscribe(f"spBv1.0/{group}/#", qos=0)
        self.port = port

    def connect(self):
        self.client.reconnect_delay_set(min_delay=1, max_delay=2)
        self.client.connect("127.0.0.1", self.port, keepalive=5)
        self.client.loop_start()

    def on_message(self, _c, _u, msg):
        parts = msg.topic.split("/")
        if len(parts) < 4:
            return
        kind = parts[2]
        device = parts[4] if len(parts) > 4 else None
        if kind in ("NCMD", "DCMD"):
            return  # our own commands
        p = Payload()
        try:
            p.ParseFromString(msg.payload)
        except Exception as e:  # noqa: BLE001 - counted as a failure
            with self.lock:
                self.seq_errors.append(f"undecodable {kind}: {e}")
            return
        with self.lock:
            self.messages.append((time.time(), kind, device, p))
            if kind == "NDEATH":
                self.ndeaths.append([metric_value(m) for m in p.metrics if m.name == "bdSeq"])
                return
            if kind == "NBIRTH":
                self.last_seq = p.seq
                if p.seq != 0:
                    self.seq_errors.append(f"NBIRTH seq {p.seq}")
                self.births = {}
                self.bd_seq = next((metric_value(m) for m in p.metrics if m.name == "bdSeq"), None)
                return
            if self.last_seq is not None and p.HasField("seq"):
                want = (self.last_seq + 1) % 256
                if p.seq != want:
                    self.seq_errors.append(f"{kind} {device}: seq {p.seq} after {self.last_seq}")
                self.last_seq = p.seq
            if kind == "DBIRTH":
                aliases = {}
                for m in p.metrics:
                    aliases[m.alias] = (m.name, m.datatype)
                    self.record(m.name, m, historical=False)
                self.births[device] = aliases
            elif kind == "DDATA":
                aliases = self.births.get(device)
                if aliases is None:
                    # Before the first NBIRTH seen, the edge's session was
                    # born before this host subscribed (it then asks for a
                    # rebirth): its data cannot be read yet, and is no fault
                    # of the edge's. After one, data before its birth is.
                    if self.last_seq is not None:
                        self.seq_errors.append(f"DDATA for {device} before its DBIRTH")
                    else:
                        self.before_first_birth += 1
                    return
                for m in p.metrics:
                    if m.name:
                        self.seq_errors.append(f"DDATA metric by name {m.name} (expected alias only)")
                    known = aliases.get(m.alias)
                    if known is None:
                        self.seq_errors.append(f"DDATA alias {m.alias} not in {device}'s DBIRTH")
                        continue
                    self.record(known[0], m, historical=m.is_historical)
            elif kind == "DDEATH":
                self.births.pop(device, None)

    def record(self, name, m, historical):
        q = props(m).get("Quality")
        self.history.setdefault(name, []).append((m.timestamp, metric_value(m), q, historical))

    def count(self, kind):
        with self.lock:
            return sum(1 for _, k, _, _ in self.messages if k == kind)

    def command(self, kind, device, payload_bytes):
        topic = f"spBv1.0/{self.group}/{kind}/{self.node}" + (f"/{device}" if device else "")
        self.client.publish(topic, payload_bytes, qos=0).wait_for_publish()

    def rebirth(self):
        p = Payload()
        m = p.metrics.add()
        m.name = "Node Control/Rebirth"
        m.datatype = 11
        m.boolean_value = True
        self.command("NCMD", None, p.SerializeToString())


class Api:
    def __init__(self, base, creds):
        self.base = base
        jar = http.cookiejar.CookieJar()
        self.opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(jar))
        user = password = None
        with open(creds) as f:
            for line in f:
                parts = line.split()
                if len(parts) >= 3 and parts[0] == "administrator":
                    user, password = parts[1], parts[2]
        body = json.dumps({"username": user, "password": password}).encode()
        req = urllib.request.Request(base + "/api/session", data=body, headers={"Content-Type": "application/json"})
        self.opener.open(req, timeout=10).read()

    def get(self, path):
        with self.opener.open(self.base + path, timeout=20) as r:
            return json.loads(r.read())

    def post(self, path):
        req = urllib.request.Request(self.base + path, data=b"", method="POST", headers={"Origin": self.base})
        with self.opener.open(req, timeout=20) as r:
            return r.status

    def send(self, method, path, body):
        """A JSON request; (status, decoded answer), an HTTP error included."""
        req = urllib.request.Request(self.base + path, data=json.dumps(body).encode(), method=method,
                                     headers={"Origin": self.base, "Content-Type": "application/json"})
        try:
            with self.opener.open(req, timeout=20) as r:
                return r.status, json.loads(r.read() or b"null")
        except urllib.error.HTTPError as e:
            return e.code, json.loads(e.read() or b"null")

    def tags(self):
        return {t["name"]: t for t in self.get("/api/tags")["tags"]}

    def metrics(self):
        with self.opener.open(self.base + "/metrics", timeout=10) as r:
            text = r.read().decode()
        out = {}
        for line in text.splitlines():
            if line.startswith("gridscada_mqtt_"):
                name, value = line.rsplit(" ", 1)
                out[name] = float(value)
        return out


def quality_code(q):
    return {"good": 192, "uncertain": 64, "bad": 0}[q["code"]]


def same(a, b):
    if isinstance(a, float) or isinstance(b, float):
        if a is None or b is None:
            return False
        return a == b or (a != a and b != b) or abs(float(a) - float(b)) <= 1e-6 * max(1.0, abs(float(a)))
    return a == b


def wait_for(cond, secs, step=0.1):
    end = time.time() + secs
    while time.time() < end:
        if cond():
            return True
        time.sleep(step)
    return cond()


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def start_broker(conf, port):
    proc = subprocess.Popen(["mosquitto", "-c", conf], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for _ in range(100):
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return proc
        except OSError:
            time.sleep(0.1)
    raise SystemExit(f"FAIL setup: mosquitto did not listen on {port}")


def compare_with_api(host, api, rounds=12):
    """Every tag of /api/tags: the host's value at the API sample's time
    (births and live DDATA) has its value and quality. A sample is published
    on a change of value or quality, so the API's timestamp may be newer
    (the last read) than the one published."""
    missing = {}
    for _ in range(rounds):
        tags = api.tags()
        time.sleep(0.6)  # let the batch carrying these samples arrive
        missing = {}
        with host.lock:
            for name, t in tags.items():
                live = [x for x in host.history.get(name, []) if not x[3]]
                if not live:
                    missing[name] = "never published"
                    continue
                # The host's value at the time of the API's sample: the last
                # one published at or before it.
                at = [x for x in live if t["timestamp"] == 0 or x[0] <= t["timestamp"]]
                ts, v, q, _ = max(at, key=lambda x: x[0]) if at else live[0]
                want_q = quality_code(t["quality"])
                if not (at and same(v, t["value"]) and q == want_q):
                    missing[name] = f"api {t['value']!r} q{want_q} @{t['timestamp']}, host {(ts, v, q)}"
        if not missing:
            return len(tags), {}
    return len(tags), missing


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--broker-port", type=int, required=True)
    ap.add_argument("--mosquitto-conf", required=True)
    ap.add_argument("--base", required=True)
    ap.add_argument("--creds", required=True)
    ap.add_argument("--group", default="gridscada")
    ap.add_argument("--node", default="demo")
    ap.add_argument("--outage", type=float, default=20.0)
    ap.add_argument("--edge-pid", type=int, help="killed with SIGKILL at the end, to see its will (NDEATH)")
    args = ap.parse_args()

    broker = start_broker(args.mosquitto_conf, args.broker_port)
    host = Host(args.broker_port, args.group, args.node)
    host.connect()
    try:
        run(args, host, broker)
    finally:
        host.client.loop_stop()
        broker.terminate()
        broker.wait(5)
    print(f"{passed} passed, {failed} failed", flush=True)
    raise SystemExit(1 if failed else 0)


def run(args, host, broker):
    # The edge retries every few seconds; once connected it births. If it
    # connected before we subscribed, a rebirth request brings the births.
    if not wait_for(lambda: host.count("NBIRTH") > 0, 8):
        host.rebirth()
    check("NBIRTH received", wait_for(lambda: host.count("NBIRTH") > 0, 20), "none within 28 s")
    api = Api(args.base, args.creds)
    tags = api.tags()
    devices = sorted({t["source"]["device"] for t in tags.values() if t.get("source")})
    ok_births = wait_for(lambda: all(d in host.births for d in devices + ["gridscada"]), 20)
    check(f"a DBIRTH for each of the {len(devices)} devices and the server's own tags",
          ok_births, f"have {sorted(host.births)}")
    with host.lock:
        nbirth = next(p for _, k, _, p in host.messages if k == "NBIRTH")
        names = {m.name for m in nbirth.metrics}
        check("NBIRTH carries bdSeq and Node Control/Rebirth", {"bdSeq", "Node Control/Rebirth"} <= names, names)
        born = {name for a in host.births.values() for name, _ in a.values()}
        dbirths = [p for _, k, _, p in host.messages if k == "DBIRTH"]
        aliases = [m.alias for p in dbirths for m in p.metrics]
        check("aliases are unique in the node", len(aliases) == len(set(aliases)), "duplicates")
        complete = all(m.name and m.HasField("alias") and m.datatype and "Quality" in props(m) and m.HasField("timestamp")
                       for p in dbirths for m in p.metrics)
        check("every DBIRTH metric has name, alias, datatype, timestamp and Quality", complete, "")
        units = [props(m).get("engUnit") for p in dbirths for m in p.metrics if props(m).get("engUnit")]
        check("units are published (engUnit)", len(units) > 0, "none")
    check("every tag of /api/tags is in a DBIRTH", set(tags) <= born, sorted(set(tags) - born)[:10])

    n, missing = compare_with_api(host, api)
    check(f"the values, qualities and timestamps of all {n} tags of /api/tags were published", not missing,
          json.dumps(dict(list(missing.items())[:8]), default=str))

    commands(args, host, api, tags)
    device_death(host, api, devices)
    rebirth(host)
    outage(args, host, api, broker)
    with host.lock:
        check("seq runs 0..255 without a gap within each session, no DDATA before its DBIRTH",
              not host.seq_errors, host.seq_errors[:5])
        bd_seq = host.bd_seq
    if args.edge_pid:
        check("gridscada still answers after the bad input and the outage",
              api.metrics().get("gridscada_mqtt_connected") == 1.0, "")
        import os
        import signal
        os.kill(args.edge_pid, signal.SIGKILL)
        died = wait_for(lambda: len(host.ndeaths) > 0, 20)
        with host.lock:
            check("kill -9: the broker publishes the NDEATH will with the session's bdSeq",
                  died and host.ndeaths[-1] == [bd_seq], (host.ndeaths, bd_seq))


def dcmd_payload(alias=None, name=None, datatype=11, value=True):
    p = Payload()
    p.timestamp = int(time.time() * 1000)
    m = p.metrics.add()
    if alias is not None:
        m.alias = alias
    if name is not None:
        m.name = name
    m.datatype = datatype
    if datatype == 11:
        m.boolean_value = value
    elif datatype == 10:
        m.double_value = value
    return p.SerializeToString()


def commands(args, host, api, tags):
    target = "SS1.Zone4.Cmd"
    t = tags.get(target)
    if t is None:
        check(f"{target} is in the demo", False, "missing")
        return
    device = t["source"]["device"]
    with host.lock:
        alias = next(a for a, (n, _) in host.births[device].items() if n == target)
    old = t["value"]
    new = not old
    before = api.metrics()
    host.command("DCMD", device, dcmd_payload(alias=alias, value=new))
    changed = wait_for(lambda: api.tags()[target]["value"] == new, 15, 0.3)
    check(f"a DCMD writes {target} = {new}: the device confirms it (/api/tags read-back)", changed, api.tags()[target])
    published = wait_for(lambda: any(v == new for _, v, _, _ in host.history.get(target, [])[-5:]), 5)
    check("the confirmed value comes back as DDATA", published, host.history.get(target, [])[-3:])
    events = api.get(f"/api/events?limit=200")
    rows = events.get("events", events) if isinstance(events, dict) else events
    text = json.dumps(rows)
    check("the DCMD write is in the event log (request and confirmation)",
          f"Sparkplug DCMD (as operator) requests {target}" in text and f"wrote {target}" in text, text[:400])
    # Back as it was, by name this time.
    host.command("DCMD", device, dcmd_payload(name=target, value=old))
    wait_for(lambda: api.tags()[target]["value"] == old, 15, 0.3)

    # Refused: read-only, not allowed by role, unknown alias/name, wrong
    # device, bad value type, malformed and oversized payloads.
    ro = next(n for n in sorted(tags) if not tags[n]["writable"] and tags[n].get("source"))
    ro_device = tags[ro]["source"]["device"]
    with host.lock:
        ro_alias = next(a for a, (n, _) in host.births[ro_device].items() if n == ro)
        sup = next(((d, a, n) for d, al in host.births.items() for a, (n, dt) in al.items()
                    if tags.get(n, {}).get("write_role") == "supervisor"), None)
    refusals = [
        ("a read-only tag", ro_device, dcmd_payload(alias=ro_alias, datatype=10, value=1.0)),
        ("an unknown alias", device, dcmd_payload(alias=987654321, value=True)),
        ("an unknown name", device, dcmd_payload(name="No.Such.Tag", value=True)),
        ("a tag of another device", "gridscada", dcmd_payload(alias=alias, value=new)),
        ("a value of the wrong type", device, dcmd_payload(alias=alias, datatype=12, value=None)),
    ]
    if sup:
        refusals.append((f"a tag whose write role is above the node's ({sup[2]})", sup[0],
                         dcmd_payload(alias=sup[1], datatype=10, value=1.0)))
    for _, dev, payload in refusals:
        host.command("DCMD", dev, payload)
    flood = Payload()
    for i in range(50):
        m = flood.metrics.add()
        m.alias = 900000000 + i
        m.datatype = 11
        m.boolean_value = True
    host.command("DCMD", device, flood.SerializeToString())
    host.command("DCMD", device, b"\xff\x01garbage not protobuf")
    host.command("DCMD", device, b"\x00" * (300 * 1024))
    host.command("NCMD", None, b"\x08")
    time.sleep(2)
    after = api.metrics()
    refused = after.get('gridscada_mqtt_commands_total{outcome="refused"}', 0) - before.get('gridscada_mqtt_commands_total{outcome="refused"}', 0)
    malformed = after.get("gridscada_mqtt_malformed_messages_total", 0) - before.get("gridscada_mqtt_malformed_messages_total", 0)
    check(f"{len(refusals)} refused DCMDs and a DCMD of 50 unknown metrics are counted",
          refused >= len(refusals) + 50, f"refused +{refused}")
    check("malformed and oversized messages are counted", malformed >= 3, f"malformed +{malformed}")
    now = api.tags()
    check(f"nothing changed: {target} is still {old}", now[target]["value"] == old, now[target]["value"])
    text = json.dumps(api.get("/api/events?limit=200"))
    check(f"no write of {ro} went out", f"requests {ro}:" not in text and f"wrote {ro}" not in text, "")
    check("refused DCMDs are in the event log", "may not write" in text and "read-only" in text, text[:300])
    check("a flood of refused metrics is summarized in the event log, not one record each",
          "30 more metrics of one DCMD" in text and text.count("may not write alias 9000000") == 20,
          text.count("may not write alias 9000000"))
    check("the edge is still up after bad input", wait_for(lambda: api.metrics().get("gridscada_mqtt_connected") == 1.0, 5), "")
    safety_tag_refuses_dcmd(host, api, device, alias, target)


def safety_tag_refuses_dcmd(host, api, device, alias, target):
    """A "Do not close" safety tag on the zone's MCB refuses a DCMD that
    would close it, like every other command path (docs/NETWORK.md)."""
    try:
        model = api.get("/api/network")
    except urllib.error.HTTPError as e:
        check("the demo has a switching network (/api/network)", False, e.code)
        return
    switch = next((w for w in model.get("switches", []) if w.get("command_tag") == target), None)
    check(f"{target} commands a switching device of the network", switch is not None,
          [w.get("command_tag") for w in model.get("switches", [])][:8])
    if switch is None:
        return
    st, placed = api.send("POST", "/api/switching/tags", {
        "device": switch["id"], "kind": "do_not_close",
        "reason": "Sparkplug test: zone out for work", "work_ref": "WO-SPB"})
    check(f"a do_not_close tag is placed on {switch['id']}", st in (200, 201), (st, placed))
    if st not in (200, 201):
        return
    before = api.tags()[target]["value"]
    host.command("DCMD", device, dcmd_payload(alias=alias, value=True))
    time.sleep(2)
    text = json.dumps(api.get("/api/events?limit=100"))
    check("a DCMD closing the tagged zone is refused, naming the safety tag, and nothing goes out",
          "write_refused" in text and "DO NOT CLOSE" in text and "Sparkplug test: zone out for work" in text
          and api.tags()[target]["value"] == before, text[:600])
    st, _ = api.send("DELETE", f"/api/switching/tags/{placed['id']}", {"reason": "Sparkplug test done"})
    check("the safety tag is removed", st == 200, st)


def messages_since(host, n, kind, device=None):
    with host.lock:
        return [p for _, k, d, p in host.messages[n:] if k == kind and (device is None or d == device)]


def device_death(host, api, devices):
    """A device that stops answering: DDEATH; back: DBIRTH with Good values."""
    device = devices[0]
    n = len(host.messages)
    api.post(f"/api/sim/devices/{device}/offline")
    died = wait_for(lambda: bool(messages_since(host, n, "DDEATH", device)), 20)
    check(f"{device} taken off line: its DDEATH", died, "none within 20 s")
    with host.lock:
        stray = [p for _, k, d, p in host.messages[n:] if k == "DDATA" and d == device]
        after_death = False
        bad_ddata = False
        for _, k, d, _p in host.messages[n:]:
            if d != device:
                continue
            if k == "DDEATH":
                after_death = True
            elif k == "DDATA" and after_death:
                bad_ddata = True
    check(f"no DDATA for {device} while it is dead", not bad_ddata, len(stray))
    n = len(host.messages)
    api.post(f"/api/sim/devices/{device}/online")
    wait_for(lambda: messages_since(host, n, "DBIRTH", device), 30)
    born = messages_since(host, n, "DBIRTH", device)
    check(f"{device} back: a new DBIRTH", bool(born), "none within 30 s")
    if born:
        q = [props(m).get("Quality") for m in born[0].metrics]
        good = wait_for(lambda: all(t["quality"]["code"] == "good" for t in api.tags().values()
                                    if (t.get("source") or {}).get("device") == device), 15)
        check(f"its DBIRTH carries its tags with quality (Good once read: {q.count(192)} of {len(q)})", good and len(q) > 0, q[:5])


def rebirth(host):
    """NCMD Node Control/Rebirth: NBIRTH (seq 0, same bdSeq) and every DBIRTH again."""
    with host.lock:
        bd = host.bd_seq
        devices = len(host.births)
    n = len(host.messages)
    host.rebirth()
    ok_ = wait_for(lambda: len(messages_since(host, n, "DBIRTH")) >= devices, 15)
    nb = messages_since(host, n, "NBIRTH")
    check(f"NCMD rebirth: NBIRTH and {devices} DBIRTHs again, same bdSeq",
          ok_ and len(nb) == 1 and nb[0].seq == 0 and host.bd_seq == bd,
          (len(nb), len(messages_since(host, n, "DBIRTH")), bd, host.bd_seq))


def outage(args, host, api, broker):
    # A tag that changes on every scan: the server's own poll counter of a device.
    tags = api.tags()
    counter = next((n for n in sorted(tags) if n.endswith(".Comm.Requests")), None)
    with host.lock:
        bd_before = host.bd_seq
    nbirths = host.count("NBIRTH")
    kill_at = int(time.time() * 1000)
    broker.kill()
    broker.wait(5)
    time.sleep(args.outage)
    restart_at = int(time.time() * 1000)
    new_broker = start_broker(args.mosquitto_conf, args.broker_port)
    broker.__dict__.update(new_broker.__dict__)  # the caller terminates "broker"
    came_back = wait_for(lambda: host.count("NBIRTH") > nbirths, 30)
    check(f"after a {args.outage:.0f} s broker outage the edge births again", came_back, "no NBIRTH within 30 s")
    with host.lock:
        check("the new session has a new bdSeq", host.bd_seq is not None and host.bd_seq != bd_before, (bd_before, host.bd_seq))
    wait_for(lambda: api.metrics().get("gridscada_mqtt_buffered_samples", 1) == 0, 15)
    time.sleep(1.5)
    m = api.metrics()
    check("the edge counted the reconnect", m.get("gridscada_mqtt_reconnects_total", 0) >= 1, m)
    check("buffered samples were replayed", m.get("gridscada_mqtt_replayed_samples_total", 0) > 0, m)
    check("no sample was dropped", m.get("gridscada_mqtt_dropped_samples_total", 1) == 0, m)
    if counter is None:
        check("a counter tag to follow through the outage", False, "none")
        return
    with host.lock:
        seen = sorted(host.history.get(counter, []))
    window = [(ts, v, h) for ts, v, _, h in seen if kill_at <= ts <= restart_at]
    historical = [x for x in window if x[2]]
    check(f"{counter}: samples of the outage window arrive as historical data",
          len(historical) > 0 and len(historical) >= 0.9 * len(window), f"{len(historical)} of {len(window)}")
    # No gap: consecutive values of a counter differ by the requests of one scan.
    values = sorted({v for ts, v, _ in window})
    steps = [b - a for a, b in zip(values, values[1:])]
    big = [s for s in steps if s > 4 * max(1, min(steps or [1]))]
    span_ok = window and window[0][0] - kill_at < 3000 and restart_at - window[-1][0] < 3000
    check(f"{counter}: no gap in the outage window ({len(window)} samples, steps {min(steps or [0])}..{max(steps or [0])})",
          not big and bool(span_ok), f"big steps {big[:5]}, first {window[:1]}, last {window[-1:]}")


if __name__ == "__main__":
    main()
