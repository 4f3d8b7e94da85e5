#!/usr/bin/env python3
"""Scale-out figure of the central Sparkplug host: SITES edge nodes of TAGS
metrics each, every metric changing once a second, through Debian's
mosquitto into one central gridscada (`demo --config`, historian on).
Reports the central's CPU and RSS, whether it kept up (every NDATA taken,
none refused for a seq gap), and the historian's drops.

    target/test-venv/bin/python scripts/bench-sparkplug-host.py --sites 10 --tags 10000

GRIDSCADA_BIN picks the binary (default target/release/gridscada). The load
is pre-encoded: a Payload is its header (timestamp, seq) followed by one of
four pre-serialized metric lists (protobuf concatenation merges them), so
the Python side costs little besides the socket.
"""

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request

import paho.mqtt.client as mqtt

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "e2e"))
from sparkplug_edge_sim import Payload, add_metric, now_ms, INT64, DOUBLE  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    p = s.getsockname()[1]
    s.close()
    return p


def cpu_seconds(pid):
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def rss_mb(pid):
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


def metrics_of(base):
    out = {}
    with urllib.request.urlopen(base + "/metrics", timeout=10) as r:
        for line in r.read().decode().splitlines():
            if line.startswith("gridscada_") and " " in line and not line.startswith("#"):
                k, v = line.rsplit(" ", 1)
                out[k] = float(v)
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sites", type=int, default=10)
    ap.add_argument("--tags", type=int, default=1000)
    ap.add_argument("--seconds", type=int, default=30)
    args = ap.parse_args()
    binary = os.environ.get("GRIDSCADA_BIN", os.path.join(ROOT, "target", "release", "gridscada"))
    tmp = tempfile.mkdtemp(prefix="bench-spb-host-")
    mport, hport = free_port(), free_port()
    base = f"http://127.0.0.1:{hport}"
    procs = []
    try:
        with open(f"{tmp}/mosquitto.conf", "w") as f:
            f.write(f"listener {mport} 127.0.0.1\nallow_anonymous true\npersistence false\n"
                    "max_queued_messages 100000\n")
        procs.append(subprocess.Popen(["/usr/sbin/mosquitto", "-c", f"{tmp}/mosquitto.conf"],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        os.makedirs(f"{tmp}/central")
        with open(f"{tmp}/central/gridscada.toml", "w") as f:
            f.write(f"""[mqtt]
broker = "mqtt://127.0.0.1:{mport}"
group = "Bench"
[mqtt.host]
host_id = "central"
max_tags = {args.sites * args.tags + 10}
max_message_bytes = 268435456
""")
        central = subprocess.Popen([binary, "demo", "--config", f"{tmp}/central", "--http",
                                    f"127.0.0.1:{hport}", "--data", f"{tmp}/data"],
                                   stdout=open(f"{tmp}/central.log", "w"), stderr=subprocess.STDOUT)
        procs.append(central)
        for _ in range(300):
            try:
                urllib.request.urlopen(base + "/healthz", timeout=1)
                break
            except OSError:
                time.sleep(0.1)

        # Four pre-encoded metric lists per site (values base+k), by alias.
        variants = []
        for k in range(4):
            p = Payload()
            for a in range(1, args.tags + 1):
                m = p.metrics.add()
                m.alias = a
                m.double_value = a + k * 0.25
            variants.append(p.SerializeToString())
        clients, seqs = [], []
        for s in range(args.sites):
            node = f"site-{s:03d}"
            c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"bench-{node}")
            c.max_queued_messages_set(0)
            c.connect("127.0.0.1", mport, keepalive=30)
            c.loop_start()
            birth = Payload(timestamp=now_ms(), seq=0)
            add_metric(birth, "bdSeq", None, INT64, 0)
            for a in range(1, args.tags + 1):
                add_metric(birth, f"Bay{a // 100}/M{a}", a, DOUBLE, float(a))
            c.publish(f"spBv1.0/Bench/NBIRTH/{node}", birth.SerializeToString(), qos=0)
            clients.append((node, c))
            seqs.append(1)
        want = args.sites * args.tags
        for _ in range(600):
            m = metrics_of(base)
            if m.get("gridscada_sparkplug_host_tags", 0) >= want:
                break
            time.sleep(0.5)
        print(f"births taken: {int(metrics_of(base).get('gridscada_sparkplug_host_tags', 0))} tags")

        m0 = metrics_of(base)
        c0, t0 = cpu_seconds(central.pid), time.monotonic()
        rss_peak = 0.0
        tick = time.monotonic()
        for second in range(args.seconds):
            body = variants[second % 4]
            for i, (node, c) in enumerate(clients):
                head = Payload(timestamp=now_ms(), seq=seqs[i]).SerializeToString()
                seqs[i] = (seqs[i] + 1) % 256
                c.publish(f"spBv1.0/Bench/NDATA/{node}", head + body, qos=0)
            rss_peak = max(rss_peak, rss_mb(central.pid))
            tick += 1.0
            time.sleep(max(0.0, tick - time.monotonic()))
        time.sleep(2)
        cpu = (cpu_seconds(central.pid) - c0) / (time.monotonic() - t0)
        m1 = metrics_of(base)
        taken = m1.get('gridscada_sparkplug_host_messages_total{type="NDATA"}', 0) - \
            m0.get('gridscada_sparkplug_host_messages_total{type="NDATA"}', 0)
        result = {
            "sites": args.sites, "tags_per_site": args.tags, "seconds": args.seconds,
            "metric_changes_per_s": args.sites * args.tags,
            "ndata_sent": args.sites * args.seconds, "ndata_taken": int(taken),
            "refused": {k.split('"')[1]: v for k, v in m1.items()
                        if k.startswith("gridscada_sparkplug_host_refused_total") and v},
            "central_cpu_percent_of_one_core": round(cpu * 100, 1),
            "central_rss_mb_peak": round(rss_peak, 1),
            "historian_dropped": m1.get("gridscada_historian_dropped_total", 0),
        }
        print(json.dumps(result))
    finally:
        for p in reversed(procs):
            p.terminate()
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


if __name__ == "__main__":
    main()
