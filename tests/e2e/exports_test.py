"""CSV exports of a running `gridscada demo` over HTTP (run by exports.sh).

A million events are written straight into the demo's SQLite store (one
statement, while the server runs), then `/api/events.csv` is downloaded
with a filter that selects exactly them, while the server's resident memory
(VmRSS of /proc/PID/status) is sampled every 20 ms:

- every row arrives, newest first, with the header first;
- text that a spreadsheet would run as a formula (`=`, `+`, `-`, `@`) is
  defused with a leading `'`, as in the trend export;
- the server's memory grows by less than EXPORT_RSS_LIMIT_MIB during the
  export: the rows are streamed, never held (the CSV itself is ~90 MB);
- the alarm history and dispatch history exports answer with their header,
  and the filters of their lists.

Prints the measured figures and "N passed, M failed" last; exits non-zero
on any failure.
"""

import json
import os
import socket
import sqlite3
import subprocess
import shutil
import sys
import tempfile
import threading
import time
import urllib.request

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.environ.get("GRIDSCADA_BIN") or os.path.join(
    os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target")), "debug", "gridscada"
)
ROWS = int(os.environ.get("EXPORT_ROWS", "1000000"))
RSS_LIMIT_MIB = float(os.environ.get("EXPORT_RSS_LIMIT_MIB", "40"))
# Every this-many-th row has a message a spreadsheet would run as a formula.
FORMULA_EVERY = 1000

passed = 0
failed = 0


def check(cond, what, detail=""):
    global passed, failed
    if cond:
        passed += 1
        print(f"ok   {what}", flush=True)
    else:
        failed += 1
        print(f"FAIL {what}{': ' + str(detail) if detail else ''}", flush=True)
    return cond


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def rss_kib(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


class Server:
    def __init__(self, tmp):
        self.data = os.path.join(tmp, "data")
        self.port = free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        self.log = open(os.path.join(tmp, "server.log"), "w")
        self.proc = subprocess.Popen(
            [BIN, "demo", "--http", f"127.0.0.1:{self.port}", "--data", self.data],
            stdout=self.log, stderr=subprocess.STDOUT,
        )
        deadline = time.time() + 60
        while time.time() < deadline:
            try:
                if os.path.exists(os.path.join(self.data, "credentials.txt")):
                    urllib.request.urlopen(self.base + "/healthz", timeout=2).read()
                    break
            except OSError:
                pass
            if self.proc.poll() is not None:
                sys.exit(f"FAIL setup: the demo exited ({self.proc.returncode})")
            time.sleep(0.2)
        else:
            sys.exit("FAIL setup: the demo did not answer in 60 s")
        for line in open(os.path.join(self.data, "credentials.txt")):
            parts = line.split()
            if parts and parts[0] == "administrator":
                user, password = parts[1], parts[2]
        body = json.dumps({"username": user, "password": password}).encode()
        req = urllib.request.Request(self.base + "/api/session", data=body,
                                     headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(req) as r:
            self.cookie = r.headers["Set-Cookie"].split(";")[0]

    def get(self, path):
        req = urllib.request.Request(self.base + path)
        req.add_header("Cookie", self.cookie)
        return urllib.request.urlopen(req, timeout=120)

    def stop(self):
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def database(data):
    for name in os.listdir(data):
        if name.endswith(".db"):
            return os.path.join(data, name)
    sys.exit(f"FAIL setup: no SQLite database in {data}: {os.listdir(data)}")


def main():
    tmp = tempfile.mkdtemp(prefix="gridscada-exports-")
    srv = Server(tmp)
    try:
        run(srv)
    finally:
        srv.stop()
    print(f"{passed} passed, {failed} failed")
    # Kept for a look when something failed; otherwise gone (130 MB a run).
    if failed:
        print(f"(the demo's data is in {tmp})")
    else:
        shutil.rmtree(tmp, ignore_errors=True)
    sys.exit(1 if failed else 0)


def run(srv):
    db = sqlite3.connect(database(srv.data), timeout=60)
    t0 = time.time()
    # ts from 1 000 000 000 ms on, one per ms: oldest first by id and ts.
    db.execute(
        """INSERT INTO events (ts, user_name, source, kind, message)
           WITH RECURSIVE n(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM n WHERE i < ?)
           SELECT 1000000000 + i, 'bulk-user', 'export-test', 'command',
                  CASE WHEN i % ? = 0 THEN '=HYPERLINK(\"http://evil\",\"row ' || i || '\")'
                       ELSE 'breaker ' || i || ' closed, by the book' END
           FROM n""",
        (ROWS, FORMULA_EVERY),
    )
    db.commit()
    db.close()
    print(f"     {ROWS} events written in {time.time() - t0:.1f} s", flush=True)

    pid = srv.proc.pid
    time.sleep(1)
    before = rss_kib(pid)
    peak = [before]
    done = threading.Event()

    def sample():
        while not done.is_set():
            try:
                peak[0] = max(peak[0], rss_kib(pid))
            except OSError:
                return
            time.sleep(0.02)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    t0 = time.time()
    rows = 0
    size = 0
    header = None
    first = last = None
    formulas = defused = 0
    prev_ts = None
    ordered = True
    with srv.get("/api/events.csv?source=export-test") as r:
        check(r.headers.get("Content-Type", "").startswith("text/csv"), "events.csv is text/csv",
              r.headers.get("Content-Type"))
        check("attachment" in r.headers.get("Content-Disposition", ""), "events.csv is a download")
        for raw in r:
            size += len(raw)
            line = raw.decode("utf-8").rstrip("\n")
            if header is None:
                header = line
                continue
            rows += 1
            parts = line.split(",", 5)
            ts = int(parts[1])
            if prev_ts is not None and ts >= prev_ts:
                ordered = False
            prev_ts = ts
            if first is None:
                first = line
            last = line
            msg = parts[5]
            if "HYPERLINK" in msg:
                formulas += 1
                if msg.startswith("\"'=HYPERLINK("):
                    defused += 1
    elapsed = time.time() - t0
    done.set()
    sampler.join()
    growth_mib = (peak[0] - before) / 1024
    print(f"     events.csv: {rows} rows, {size / 1e6:.1f} MB in {elapsed:.1f} s "
          f"({rows / max(elapsed, 1e-9):,.0f} rows/s); server RSS {before / 1024:.1f} MiB before, "
          f"peak {peak[0] / 1024:.1f} MiB (+{growth_mib:.1f} MiB)", flush=True)
    check(header == "time_utc,ts_ms,user,source,type,message", "the header comes first", header)
    check(rows == ROWS, f"all {ROWS} rows arrive", rows)
    check(ordered, "newest first, like the event screen")
    check(first is not None and f",{1000000000 + ROWS}," in first, "the newest row first", first)
    check(last is not None and last.endswith(",bulk-user,export-test,command,\"breaker 1 closed, by the book\""),
          "the oldest row last, its comma quoted", last)
    check(formulas == ROWS // FORMULA_EVERY and defused == formulas,
          f"every formula is defused ({defused} of {formulas})")
    check(growth_mib < RSS_LIMIT_MIB,
          f"the server's memory grows by less than {RSS_LIMIT_MIB:.0f} MiB while it sends {size / 1e6:.0f} MB",
          f"+{growth_mib:.1f} MiB")

    # A filter narrows the export like the list: the text filter of the screen.
    with srv.get("/api/events.csv?source=export-test&text=breaker%20999999%20") as r:
        lines = r.read().decode().splitlines()
    check(len(lines) == 2 and ",\"breaker 999999 closed" in lines[1], "the text filter applies", lines)

    # The alarm history and dispatch history exports, with their lists' filters.
    with srv.get("/api/alarms/history.csv?min_priority=0") as r:
        lines = r.read().decode().splitlines()
    check(lines and lines[0].startswith("time_utc,ts_ms,alarm,tag,kind,from_state,to_state,cause"),
          "alarm history CSV header", lines[:1])
    deadline = time.time() + 30
    while True:
        with srv.get("/api/dispatch/history.csv") as r:
            lines = r.read().decode().splitlines()
        if len(lines) > 1 or time.time() > deadline:
            break
        time.sleep(1)
    check(lines[0] == "time_utc,ts_ms,status,mode,objective,solve_ms,reason,setpoints"
          and len(lines) > 1, "dispatch history CSV with the demo's dispatches", lines[:2])
    try:
        srv.get("/api/dispatch/history.csv?from=10&to=1")
        check(False, "a reversed range is refused")
    except urllib.error.HTTPError as e:
        check(e.code == 400, "a reversed range is refused", e.code)


if __name__ == "__main__":
    main()
