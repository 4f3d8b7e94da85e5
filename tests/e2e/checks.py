"""What the telecontrol end-to-end harnesses (iec104_test.py, dnp3_test.py,
iec61850_test.py, sim_stations_test.py) share: one line per check ("ok"/"FAIL") with the
counts for the summary, notes for the record, a free loopback port, and a
bounded wait on a condition."""

import http.cookiejar
import json
import os
import socket
import time
import urllib.error
import urllib.request

PASSED = 0
FAILED = 0
NOTES = []


def check(ok, what, detail=""):
    global PASSED, FAILED
    if ok:
        PASSED += 1
        print(f"ok   {what}", flush=True)
    else:
        FAILED += 1
        print(f"FAIL {what}" + (f": {detail}" if detail else ""), flush=True)


def note(what):
    """Something seen that is not a check (printed, not counted)."""
    NOTES.append(what)
    print(f"note {what}", flush=True)


def free_port(host="127.0.0.1"):
    s = socket.socket()
    s.bind((host, 0))
    port = s.getsockname()[1]
    s.close()
    return port


def wait_for(cond, timeout, step=0.1):
    """`cond()`'s first truthy value within `timeout` seconds, else its last."""
    end = time.time() + timeout
    last = None
    while time.time() < end:
        last = cond()
        if last:
            return last
        time.sleep(step)
    return last


# The server's API with a logged-in session (dnp3_test.py, iec61850_test.py).
class Api:
    def __init__(self, base):
        self.base = base
        self.opener = urllib.request.build_opener(
            urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))

    def call(self, method, path, body=None, timeout=30):
        data = json.dumps(body).encode() if body is not None else None
        req = urllib.request.Request(self.base + path, data=data, method=method, headers={
            "Content-Type": "application/json", "Origin": self.base})
        try:
            with self.opener.open(req, timeout=timeout) as r:
                raw = r.read()
                try:
                    return r.status, json.loads(raw or b"null")
                except ValueError:
                    return r.status, raw.decode()
        except urllib.error.HTTPError as e:
            return e.code, json.loads(e.read() or b"null")
        except OSError as e:
            return 0, {"error": str(e)}

    def tag(self, name):
        status, body = self.call("GET", f"/api/tags/{name}")
        return body if status == 200 else None

    def device(self, name):
        status, body = self.call("GET", "/api/devices")
        if status != 200:
            return None, None
        dev = next((d for d in body.get("devices", []) if d.get("name") == name), None)
        link = next((l for l in body.get("links", []) if name in l.get("devices", [])), None)
        return dev, link

    def metrics(self):
        try:
            with urllib.request.urlopen(self.base + "/metrics", timeout=10) as r:
                return r.read().decode()
        except OSError as e:
            return f"# unreadable: {e}"

    def active_alarms(self):
        """The keys of the active alarms."""
        status, body = self.call("GET", "/api/alarms")
        return sorted(a.get("key") for a in (body or {}).get("alarms", []) if a.get("active")) if status == 200 else None

    def healthz(self):
        try:
            with urllib.request.urlopen(self.base + "/healthz", timeout=5) as r:
                return r.status
        except urllib.error.HTTPError as e:
            return e.code
        except OSError:
            return 0


def login(base, data, proc):
    creds = os.path.join(data, "credentials.txt")
    if not wait_for(lambda: (os.path.exists(creds) and os.path.getsize(creds) > 0) or proc.poll() is not None, 60):
        return None, None
    api = Api(base)
    wait_for(lambda: api.healthz() in (200, 503), 30, 0.2)
    user, password = next(l.split()[1:3] for l in open(creds) if l.startswith("administrator"))
    status, _ = api.call("POST", "/api/session", {"username": user, "password": password})
    return (api, user) if status == 200 else (None, None)
