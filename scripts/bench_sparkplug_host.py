#!/usr/bin/env python3
"""The Sparkplug host side of scripts/bench-sparkplug.sh: subscribes to the
group, decodes every DDATA with the Tahu payload classes (protobuf's upb
backend), and measures change-to-receipt latency from each metric's own
timestamp (the wall time of the change). Prints counts, p50/p99/max latency,
and its own CPU, after WARMUP seconds, over SECONDS."""

import argparse
import resource
import threading
import time

import paho.mqtt.client as mqtt
from google.protobuf.internal import api_implementation
from mqtt_spb_wrapper.spb_protobuf import sparkplug_b_pb2 as spb

ap = argparse.ArgumentParser()
ap.add_argument("--port", type=int, required=True)
ap.add_argument("--group", default="bench")
ap.add_argument("--warmup", type=float, default=10)
ap.add_argument("--seconds", type=float, default=20)
args = ap.parse_args()

lock = threading.Lock()
state = {"measuring": False, "metrics": 0, "messages": 0, "births": 0, "lat": [], "historical": 0}


def on_message(_c, _u, msg):
    kind = msg.topic.split("/")[2]
    p = spb.Payload.FromString(msg.payload)
    now = time.time() * 1000.0
    with lock:
        if kind == "DBIRTH":
            state["births"] += 1
        if kind != "DDATA" or not state["measuring"]:
            return
        state["messages"] += 1
        lat = state["lat"]
        for m in p.metrics:
            if m.is_historical:
                state["historical"] += 1
                continue
            lat.append(now - m.timestamp)
        state["metrics"] += len(p.metrics)


c = mqtt.Client(client_id="bench-host")
c.on_message = on_message
c.on_connect = lambda cl, u, f, rc: cl.subscribe(f"spBv1.0/{args.group}/#", qos=0)
c.connect("127.0.0.1", args.port, keepalive=30)
c.loop_start()
time.sleep(args.warmup)
cpu0 = time.process_time()
with lock:
    state["measuring"] = True
time.sleep(args.seconds)
with lock:
    state["measuring"] = False
    lat = sorted(state["lat"])
cpu1 = time.process_time()
c.loop_stop()


def pct(q):
    return lat[min(len(lat) - 1, int(q * len(lat)))] if lat else float("nan")


print(
    f"host ({api_implementation.Type()} protobuf): {state['births']} DBIRTH, {state['messages']} DDATA, "
    f"{state['metrics']} metrics in {args.seconds:.0f} s ({state['metrics'] / args.seconds:,.0f}/s), "
    f"latency p50 {pct(0.5):.1f} ms, p99 {pct(0.99):.1f} ms, max {lat[-1] if lat else float('nan'):.1f} ms, "
    f"host CPU {(cpu1 - cpu0) / args.seconds * 100:.0f} %, host peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024} MiB",
    flush=True,
)
