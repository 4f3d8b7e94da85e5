"""The MQTT notification channel against Debian's mosquitto (run by
notify_mqtt.sh), with a paho-mqtt subscriber.

`gridscada demo` of the second test plant (tests/plants/three-panels), with
`[mqtt]` naming the test broker and a `channel = "mqtt"` route for RTU1's
communication alarm:

- taking RTU1 off line publishes the alarm as JSON (kind, alarm key,
  priority, contact, link into the HMI) on `{topic}/urgent`, the topic of
  its priority band, and on no other band;
- with the broker down, delivery fails (counted in /metrics); once the
  broker is back, the outbox's retry delivers the next alarm.

Prints "N passed, M failed" last; exits non-zero on any failure.
"""

import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time

import paho.mqtt.client as mqtt

import notify_test as nt
from notify_test import ROOT, Server, free_port, metric, wait_for

HMI = "https://scada.example.test/scada"
TOPIC = "site1/alarms"

ROUTE = """
[mqtt]
broker = "mqtt://127.0.0.1:{port}"
group = "NotifyTest"

[[notify]]
name = "control-room"
channel = "mqtt"
tags = ["RTU1:comm"]
hmi_url = "{hmi}"
[notify.mqtt]
topic = "{topic}"
[[notify.contact]]
name = "Control room"
address = "cr-desk-1"
"""


class Broker:
    def __init__(self, tmp, port):
        self.conf = os.path.join(tmp, "mosquitto.conf")
        with open(self.conf, "w") as f:
            f.write(f"listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n")
        self.log = open(os.path.join(tmp, "mosquitto.log"), "ab")
        self.port = port
        self.proc = None

    def start(self):
        exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
        self.proc = subprocess.Popen([exe, "-c", self.conf], stdout=self.log, stderr=subprocess.STDOUT)
        time.sleep(0.5)

    def stop(self):
        if self.proc:
            self.proc.terminate()
            self.proc.wait(10)
            self.proc = None


class Subscriber:
    """Everything published under TOPIC, resubscribed on every reconnect."""

    def __init__(self, port):
        self.got = []
        self.lock = threading.Lock()
        self.c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="notify-test-sub")
        self.c.on_connect = lambda c, u, f, rc, p: c.subscribe(TOPIC + "/#", qos=1)
        self.c.on_message = self.on_message
        self.c.reconnect_delay_set(0.2, 1)
        self.c.connect_async("127.0.0.1", port)
        self.c.loop_start()

    def on_message(self, c, u, msg):
        with self.lock:
            self.got.append((msg.topic, json.loads(msg.payload)))

    def messages(self):
        with self.lock:
            return self.got[:]


def main():
    tmp = tempfile.mkdtemp(prefix="gs-notify-mqtt-")
    try:
        run(tmp)
    finally:
        if nt.failed:
            print("---- server log (tail)")
            log = os.path.join(tmp, "server.log")
            if os.path.exists(log):
                print("\n".join(l for l in open(log, errors="replace").read().splitlines()
                                if "panicked" in l or "ERROR" in l or "WARN" in l)[-6000:])
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"{nt.passed} passed, {nt.failed} failed")
    sys.exit(1 if nt.failed else 0)


def run(tmp):
    port = free_port()
    broker = Broker(tmp, port)
    broker.start()
    sub = Subscriber(port)
    plant = os.path.join(tmp, "plant")
    shutil.copytree(os.path.join(ROOT, "tests", "plants", "three-panels"), plant)
    nt.name_site(os.path.join(plant, "gridscada.toml"))
    with open(os.path.join(plant, "gridscada.toml"), "a") as f:
        f.write(ROUTE.format(port=port, hmi=HMI, topic=TOPIC))
    server = Server(plant, os.path.join(tmp, "data"), free_port(), os.path.join(tmp, "server.log"))
    server.start()
    try:
        # 1. An alarm, on the topic of its priority band.
        server.call("POST", "/api/sim/devices/RTU1/offline")
        nt.check(wait_for(lambda: server.alarm("RTU1:comm"), 20), "RTU1's comm alarm stands")
        got = wait_for(lambda: [m for m in sub.messages() if m[1].get("kind") == "alarm"], 30)
        if nt.check(got, "the subscriber receives the alarm"):
            topic, j = got[0]
            prio = j["alarm"]["priority"]
            nt.check(prio >= 800 and topic == f"{TOPIC}/urgent", "published on the topic of its priority band",
                     (topic, prio))
            nt.check(j["alarm"]["key"] == "RTU1:comm" and j["contact"] == "Control room" and j["address"] == "cr-desk-1"
                     and j["link"] == HMI + "/#/alarms" and j["route"] == "control-room",
                     "the JSON carries the alarm, the contact and the link into the HMI", j)
            nt.check(j.get("site") == nt.SITE, "the JSON names the site", j)
            nt.check(all(t == f"{TOPIC}/urgent" for t, _ in sub.messages()), "nothing on the other bands",
                     [t for t, _ in sub.messages()])
        alarm = server.alarm("RTU1:comm")
        server.call("POST", "/api/alarms/ack", {"ids": [alarm["id"]]})
        server.call("POST", "/api/sim/devices/RTU1/online")
        wait_for(lambda: not (server.alarm("RTU1:comm") or {}).get("active"), 30)

        # 2. The broker down: the attempt fails and is counted; back up, the retry delivers.
        before = len(sub.messages())
        broker.stop()
        server.call("POST", "/api/sim/devices/RTU1/offline")
        failing = wait_for(lambda: (metric(server.metrics(), "gridscada_notifications_failed_attempts_total",
                                           "control-room") or 0) >= 1, 40)
        nt.check(failing, "with the broker down, the failed attempt is counted in /metrics")
        nt.check(len(sub.messages()) == before, "nothing was delivered meanwhile")
        broker.start()
        again = wait_for(lambda: len(sub.messages()) > before, 60)
        nt.check(again, "once the broker is back, the retry delivers the alarm",
                 metric(server.metrics(), "gridscada_notifications_pending"))
        sent = server.call("GET", "/api/events?type=notification&limit=50") or {}
        nt.check(any("control-room" in (e.get("message") or "") or e.get("source") == "notify" for e in sent.get("events", [])),
                 "every notification sent is an event", sent)
    finally:
        server.call("POST", "/api/sim/devices/RTU1/online")
        server.stop()
        sub.c.loop_stop()
        broker.stop()


if __name__ == "__main__":
    main()
