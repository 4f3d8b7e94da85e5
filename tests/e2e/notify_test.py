"""Alarm notification against real local peers (run by notify.sh).

An SMTP sink (aiosmtpd, STARTTLS required, with a self-signed certificate
the server is told to trust) and a webhook sink (http.server, checking the
HMAC-SHA256 signature) receive what `gridscada demo` sends for the alarms of
the second test plant (tests/plants/three-panels), raised by taking its
simulated devices off line:

- the on-call contact gets a mail with the alarm in the subject and the link
  into the HMI in the body, over STARTTLS; the webhook gets a signed JSON;
- unacknowledged, the alarm escalates to the next contact; once
  acknowledged, the third contact is never told;
- a flood of comm alarms gives one mail and one summary, not one per alarm;
- with the webhook down, delivery fails (counted in /metrics, a system alarm
  stands), survives a restart of the server, and goes out once the webhook
  is back; every notification sent is an event.

Prints "N passed, M failed" last; exits non-zero on any failure.
"""

import email
import email.policy
import hashlib
import hmac
import http.server
import json
import os
import shutil
import socket
import ssl
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

from aiosmtpd.controller import Controller

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.environ.get("GRIDSCADA_BIN") or os.path.join(
    os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target")), "debug", "gridscada"
)
SECRET = "webhook-test-key-\u00e9"  # non-ASCII: the key is bytes of UTF-8
HMI = "https://scada.example.test/scada"
LINK = HMI + "/#/alarms"

passed = 0
failed = 0


def ok(what):
    global passed
    passed += 1
    print(f"ok   {what}", flush=True)


def bad(what):
    global failed
    failed += 1
    print(f"FAIL {what}", flush=True)


def check(cond, what, detail=""):
    if cond:
        ok(what)
    else:
        bad(f"{what}{': ' + str(detail) if detail else ''}")
    return cond


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def wait_for(pred, timeout, step=0.2):
    end = time.time() + timeout
    while time.time() < end:
        v = pred()
        if v:
            return v
        time.sleep(step)
    return pred()


class Mailbox:
    """aiosmtpd handler: keeps every mail with whether STARTTLS was on."""

    def __init__(self):
        self.mails = []
        self.lock = threading.Lock()

    async def handle_DATA(self, server, session, envelope):
        msg = email.message_from_bytes(envelope.content, policy=email.policy.default)
        with self.lock:
            self.mails.append(
                {
                    "to": list(envelope.rcpt_tos),
                    "subject": str(msg["subject"]),
                    "body": msg.get_content(),
                    "tls": session.ssl is not None,
                }
            )
        return "250 OK"

    def to(self, address):
        with self.lock:
            return [m for m in self.mails if address in m["to"]]


class Hooks:
    def __init__(self):
        self.calls = []
        self.lock = threading.Lock()


def start_webhook(port, hooks):
    class Handler(http.server.BaseHTTPRequestHandler):
        def do_POST(self):
            body = self.rfile.read(int(self.headers.get("Content-Length", "0")))
            want = "sha256=" + hmac.new(SECRET.encode(), body, hashlib.sha256).hexdigest()
            good = hmac.compare_digest(self.headers.get("X-Gridscada-Signature", ""), want)
            with hooks.lock:
                hooks.calls.append({"path": self.path, "good": good, "json": json.loads(body)})
            self.send_response(200 if good else 401)
            self.send_header("Content-Length", "0")
            self.end_headers()

        def log_message(self, *a):
            pass

    srv = http.server.ThreadingHTTPServer(("127.0.0.1", port), Handler)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    return srv


class Server:
    def __init__(self, plant, data, port, log):
        self.args = [BIN, "demo", "--config", plant, "--http", f"127.0.0.1:{port}", "--data", data]
        self.base = f"http://127.0.0.1:{port}"
        self.data = data
        self.log = log
        self.proc = None
        self.cookie = None

    def start(self):
        env = dict(os.environ, GRIDSCADA_TEST_HOOK_KEY=SECRET)
        self.proc = subprocess.Popen(self.args, stdout=open(self.log, "ab"), stderr=subprocess.STDOUT, env=env)
        if not wait_for(self.healthy, 60):
            raise SystemExit(f"FAIL setup: gridscada demo did not start; see {self.log}:\n" + open(self.log).read()[-3000:])
        self.login()

    def healthy(self):
        if self.proc.poll() is not None:
            raise SystemExit(f"FAIL setup: gridscada exited {self.proc.returncode}:\n" + open(self.log).read()[-3000:])
        try:
            with urllib.request.urlopen(self.base + "/healthz", timeout=2) as r:
                return b'"status"' in r.read()
        except OSError:
            return False

    def stop(self):
        self.proc.terminate()
        self.proc.wait(60)

    def login(self):
        for line in open(os.path.join(self.data, "credentials.txt")):
            parts = line.split()
            if parts and parts[0] == "administrator":
                user, password = parts[1], parts[2]
        body = json.dumps({"username": user, "password": password}).encode()
        req = urllib.request.Request(self.base + "/api/session", data=body, headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(req) as r:
            self.cookie = r.headers["Set-Cookie"].split(";")[0]

    def call(self, method, path, body=None):
        data = json.dumps(body).encode() if body is not None else (b"" if method == "POST" else None)
        req = urllib.request.Request(self.base + path, data=data, method=method)
        req.add_header("Cookie", self.cookie)
        req.add_header("Origin", self.base)
        if body is not None:
            req.add_header("Content-Type", "application/json")
        with urllib.request.urlopen(req, timeout=10) as r:
            raw = r.read()
            return json.loads(raw) if raw else None

    def alarms(self):
        return self.call("GET", "/api/alarms")["alarms"]

    def alarm(self, key):
        return next((a for a in self.alarms() if a["key"] == key), None)

    def metrics(self):
        with urllib.request.urlopen(self.base + "/metrics") as r:
            return r.read().decode()


def metric(text, name, route=None):
    for line in text.splitlines():
        if line.startswith(name) and (route is None or f'route="{route}"' in line):
            return float(line.rsplit(" ", 1)[1])
    return None


ROUTES = """
[[notify]]
name = "on-call"
channel = "email"
min_priority = 500
tags = ["RTU1:comm"]
escalate_after_min = 0.05
hmi_url = "{hmi}"
[notify.smtp]
host = "127.0.0.1"
port = {smtp}
security = "starttls"
from = "gridscada <scada@example.test>"
ca_file = "{ca}"
[[notify.contact]]
name = "First"
address = "first@example.test"
[[notify.contact]]
name = "Second"
address = "second@example.test"
[[notify.contact]]
name = "Third"
address = "third@example.test"

[[notify]]
name = "hook"
channel = "webhook"
tags = ["RTU1:comm"]
hmi_url = "{hmi}"
[notify.webhook]
url = "http://127.0.0.1:{hook}/alarms?site=test"
secret_env = "GRIDSCADA_TEST_HOOK_KEY"
[[notify.contact]]
name = "Dispatcher"
address = "dispatch-desk"

[[notify]]
name = "flood"
channel = "email"
tags = ["P*:comm"]
flood_limit = 1
flood_window_s = 10
hmi_url = "{hmi}"
[notify.smtp]
host = "127.0.0.1"
port = {smtp}
security = "starttls"
from = "gridscada <scada@example.test>"
ca_file = "{ca}"
[[notify.contact]]
name = "Flood desk"
address = "flood@example.test"
"""


SITE = "substation-7"


def name_site(toml):
    """Gives the plant a site: several sites may feed one mailbox."""
    with open(toml) as f:
        text = f.read()
    with open(toml, "w") as f:
        f.write(text.replace("[server]\n", f'[server]\nsite = "{SITE}"\n', 1))


def main():
    tmp = tempfile.mkdtemp(prefix="gs-notify-")
    try:
        run(tmp)
    finally:
        if failed:
            print("---- server log (tail)")
            print("\n".join(l for l in open(os.path.join(tmp, "server.log"), errors="replace").read().splitlines() if "panicked" in l or "ERROR" in l or "WARN" in l)[-6000:])
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"{passed} passed, {failed} failed")
    sys.exit(1 if failed else 0)


def run(tmp):
    # The SMTP sink's certificate, made by the server's own command.
    tls = os.path.join(tmp, "tls")
    os.makedirs(tls)
    subprocess.run([BIN, "cert", "self-signed", "--out", tls, "--host", "127.0.0.1"], check=True, capture_output=True)
    ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    ctx.load_cert_chain(os.path.join(tls, "cert.pem"), os.path.join(tls, "key.pem"))
    mailbox = Mailbox()
    smtp_port = free_port()
    smtp = Controller(mailbox, hostname="127.0.0.1", port=smtp_port, tls_context=ctx, require_starttls=True)
    smtp.start()
    hooks = Hooks()
    hook_port = free_port()
    hook = start_webhook(hook_port, hooks)

    plant = os.path.join(tmp, "plant")
    shutil.copytree(os.path.join(ROOT, "tests", "plants", "three-panels"), plant)
    name_site(os.path.join(plant, "gridscada.toml"))
    with open(os.path.join(plant, "gridscada.toml"), "a") as f:
        f.write(ROUTES.format(hmi=HMI, smtp=smtp_port, hook=hook_port, ca=os.path.join(tls, "cert.pem")))
    data = os.path.join(tmp, "data")
    server = Server(plant, data, free_port(), os.path.join(tmp, "server.log"))
    server.start()

    # 1. An alarm: mail over STARTTLS with subject and link; signed webhook.
    server.call("POST", "/api/sim/devices/RTU1/offline")
    check(wait_for(lambda: server.alarm("RTU1:comm"), 20), "RTU1's comm alarm stands", [a["key"] for a in server.alarms()])
    mails = wait_for(lambda: mailbox.to("first@example.test"), 30)
    if check(mails, "the on-call contact gets a mail for RTU1's comm alarm"):
        m = mails[0]
        check("Communication lost with RTU1" in m["subject"] and "[URGENT]" in m["subject"],
              "the subject names the priority and the alarm", m["subject"])
        check(LINK in m["body"], "the mail links into the HMI's alarm list", m["body"])
        check(f"{SITE}:" in m["subject"] and f"Site: {SITE}" in m["body"],
              "the mail's subject and text name the site", (m["subject"], m["body"]))
        check(m["tls"], "the mail went over STARTTLS")
    calls = wait_for(lambda: hooks.calls[:], 30)
    if check(calls, "the webhook is called"):
        c = calls[0]
        check(c["good"], "the webhook's HMAC-SHA256 signature verifies with the shared key")
        j = c["json"]
        check(c["path"] == "/alarms?site=test" and j["kind"] == "alarm" and j["alarm"]["key"] == "RTU1:comm"
              and j["link"] == LINK and j["contact"] == "Dispatcher" and j["address"] == "dispatch-desk",
              "the webhook's JSON carries the alarm, the contact and the link", j)
        check(j.get("site") == SITE and "server" in j and j["server"] is None,
              "the webhook's JSON names the site (and no pair server: this one runs alone)", j)

    # 2. Escalation: unacknowledged after 3 s, the second contact; then ack.
    second = wait_for(lambda: mailbox.to("second@example.test"), 20)
    if check(second, "unacknowledged, the alarm escalates to the second contact"):
        check("UNACKNOWLEDGED" in second[0]["subject"] and LINK in second[0]["body"]
              and SITE in second[0]["subject"],
              "the escalation says so and links into the HMI", second[0]["subject"])
    alarm = server.alarm("RTU1:comm")
    server.call("POST", "/api/alarms/ack", {"ids": [alarm["id"]]})
    time.sleep(8)
    check(not mailbox.to("third@example.test"), "once acknowledged, the third contact is never told")
    check(len(mailbox.to("first@example.test")) == 1 and len(mailbox.to("second@example.test")) == 1,
          "each contact told once", [m["to"] for m in mailbox.mails])

    # 3. A flood: every panel device off line at once.
    devices = [d["name"] for d in server.call("GET", "/api/devices")["devices"] if d["name"] != "RTU1"]
    for d in devices:
        server.call("POST", f"/api/sim/devices/{d}/offline")
    summary = wait_for(lambda: [m for m in mailbox.to("flood@example.test") if "ALARM FLOOD" in m["subject"]], 40)
    flood = mailbox.to("flood@example.test")
    if check(summary, f"a flood of {len(devices)} comm alarms gives one summary", [m["subject"] for m in flood]):
        check(len(flood) == 2, "and one mail before it: 2 mails, not one per alarm", [m["subject"] for m in flood])
        check(SITE in summary[0]["subject"] and f"Site: {SITE}" in summary[0]["body"],
              "the summary names the site", (summary[0]["subject"], summary[0]["body"]))
        check(f"{len(devices) - 1} more alarms" in summary[0]["body"] and LINK in summary[0]["body"],
              "the summary counts the held alarms and links into the HMI", summary[0]["body"])
    check(metric(server.metrics(), "gridscada_notifications_held_total", "flood") == len(devices) - 1,
          "/metrics counts the held alarms", metric(server.metrics(), "gridscada_notifications_held_total", "flood"))
    for d in devices + ["RTU1"]:
        server.call("POST", f"/api/sim/devices/{d}/online")
    wait_for(lambda: (server.alarm("RTU1:comm") or {}).get("state") == "normal", 30)

    # 4. The webhook down: failures counted, a system alarm, then a restart.
    hook.shutdown()
    hook.server_close()
    before = len(hooks.calls)
    server.call("POST", "/api/sim/devices/RTU1/offline")
    failing = wait_for(lambda: (metric(server.metrics(), "gridscada_notifications_failed_attempts_total", "hook") or 0) >= 1, 40)
    check(failing, "a failed delivery is counted in /metrics")
    check(wait_for(lambda: server.alarm("notify:hook"), 10), "a system alarm stands while the webhook is down")
    check(metric(server.metrics(), "gridscada_notifications_pending") >= 1, "the message waits in the outbox")
    server.stop()
    hook = start_webhook(hook_port, hooks)
    server.start()
    delivered = wait_for(lambda: hooks.calls[before:], 45)
    if check(delivered, "after a restart, the queued webhook call is delivered once the webhook is back"):
        j = delivered[0]["json"]
        check(delivered[0]["good"] and j["alarm"]["key"] == "RTU1:comm", "the retried call is signed and carries the alarm")
    events = server.call("GET", "/api/events?type=notification&limit=100")["events"]
    check(any("hook to Dispatcher" in e["message"] for e in events)
          and any("on-call to Second <second@example.test>" in e["message"] for e in events)
          and any("ALARM FLOOD" in e["message"] for e in events),
          "every notification sent is an event", [e["message"] for e in events])
    server.stop()
    hook.shutdown()
    smtp.stop()


if __name__ == "__main__":
    main()
