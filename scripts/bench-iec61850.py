#!/usr/bin/env python3
"""IEC 61850 benchmarks (issue 31), each against a peer in the same run:

1. SCL import: an SCD of 100 IEDs (and one of 500), made by repeating the
   test IED of tests/e2e/iec61850_peer.py with its own name and address.
   `gridscada scl import` of every IED (a tag file each), and of one IED,
   against open61850's SCL loader (`IedModel.from_scl`, pure Python) loading
   one IED of the same file: wall time and peak RSS of each process.
2. Reports: the libiec61850 test IED changes MMXU1.TotW 5,000 times a
   second for 10 s, each change with its own timestamp (t). gridscada takes
   them by buffered report (BufTm 0, every change a report) and pushes them
   to /api/live; the latency is from the IED's t to a WebSocket client's
   arrival, p50 and p99, with the reports gridscada counted. The peer is
   open61850's client, a process of its own, on the unbuffered RCB of the
   same dataset: reports received and latency from t to its handler.

    GRIDSCADA_BIN=target/release/gridscada python3 scripts/bench-iec61850.py [import] [reports]

Needs the test venv (pyiec61850-ng, open61850, websockets). Prints one
line per figure; run it on an otherwise idle machine.
"""

import asyncio
import json
import os
import re
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(ROOT, "tests", "e2e"))
from checks import Api, free_port, login, wait_for  # noqa: E402
from iec61850_test import PeerIed  # noqa: E402

BIN = os.environ.get("GRIDSCADA_BIN", "target/release/gridscada")
TEST_SCD = os.path.join(ROOT, "server", "scl", "tests", "test.scd")


def cpu_s(pid):
    """User + system CPU seconds of a process so far."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def many_ieds(n, path):
    """An SCD of n copies of the test IED (as server/scl/tests/read.rs makes it)."""
    text = open(TEST_SCD).read()
    i0, i1 = text.index("<IED "), text.index("</IED>") + len("</IED>")
    a0, a1 = text.index("<ConnectedAP"), text.index("</ConnectedAP>") + len("</ConnectedAP>")
    ied, ap = text[i0:i1], text[a0:a1]
    aps = "".join(ap.replace('iedName="TEST"', f'iedName="IED{i}"').replace("127.0.0.1", f"10.0.{i // 250}.{i % 250 + 1}")
                  for i in range(n))
    ieds = "".join(ied.replace('name="TEST"', f'name="IED{i}"') for i in range(n))
    with open(path, "w") as f:
        f.write(text[:a0] + aps + text[a1:i0] + ieds + text[i1:])
    return os.path.getsize(path)


def timed(cmd):
    """Wall seconds and peak RSS (MiB) of a command, by GNU time."""
    r = subprocess.run(["/usr/bin/time", "-f", "%e %M", *cmd], capture_output=True, text=True, timeout=600)
    last = r.stderr.strip().splitlines()[-1]
    wall, kib = last.split()
    if r.returncode != 0:
        raise RuntimeError(f"{cmd}: {r.stderr[-500:]}")
    return float(wall), int(kib) / 1024


OPEN61850_LOAD = r"""
import sys
from open61850.server.model import IedModel
m = IedModel.from_scl(sys.argv[1], sys.argv[2])
print(len(m.names(sys.argv[2] + "LD0")))
"""


def bench_import():
    for n in (100, 500):
        with tempfile.TemporaryDirectory() as tmp:
            scd = os.path.join(tmp, f"ieds{n}.scd")
            size = many_ieds(n, scd)
            out = os.path.join(tmp, "plant")
            wall, rss = timed([BIN, "scl", "import", scd, "--out", out])
            files = len([f for f in os.listdir(out) if f.endswith(".toml")]) - 1
            print(f"import {n} IEDs ({size / 1e6:.1f} MB SCD): gridscada scl import of all {files} IEDs {wall:.2f} s, peak RSS {rss:.1f} MiB")
            one = os.path.join(tmp, "one")
            wall1, rss1 = timed([BIN, "scl", "import", scd, "--ied", f"IED{n // 2}", "--out", one])
            print(f"import {n} IEDs: gridscada scl import of one IED {wall1:.2f} s, peak RSS {rss1:.1f} MiB")
            wall2, rss2 = timed([sys.executable, "-c", OPEN61850_LOAD, scd, f"IED{n // 2}"])
            print(f"import {n} IEDs: open61850 IedModel.from_scl of one IED {wall2:.2f} s, peak RSS {rss2:.1f} MiB")


PEER_CLIENT = r"""
import queue, sys, time
from open61850.mms import MmsClient, ObjectName, rcb
from open61850.mms.report import decode_report, is_report
from open61850.data import StructureData, TimestampData
port, seconds = int(sys.argv[1]), float(sys.argv[2])
q = queue.Queue()
def stamp(v):
    if isinstance(v, TimestampData):
        return v.value.timestamp()
    if isinstance(v, StructureData):
        for m in v.members:
            t = stamp(m)
            if t is not None:
                return t
    return None
lat = []
with MmsClient.connect("127.0.0.1", port, on_information_report=lambda r: q.put((time.time(), r))) as c:
    rcb.enable(c, ObjectName("LLN0$RP$urcb01", "TESTLD0"), rcb.RcbSettings(buf_tm_ms=0))
    print("READY", flush=True)
    end = time.time() + seconds
    while time.time() < end:
        try:
            now, r = q.get(timeout=0.5)
        except queue.Empty:
            continue
        if not is_report(r):
            continue
        for e in decode_report(r).entries:
            t = stamp(e.value)
            if t is not None:
                lat.append(now - t)
lat.sort()
p = lambda f: lat[min(len(lat) - 1, int(f * len(lat)))] * 1000 if lat else float("nan")
print(f"RESULT {len(lat)} {p(0.5):.1f} {p(0.99):.1f}", flush=True)
"""


async def live_latencies(base, cookie, tag, seconds, out):
    import websockets
    url = base.replace("http", "ws") + "/api/live"
    async with websockets.connect(url, additional_headers={"Cookie": cookie, "Origin": base}, max_size=None) as ws:
        await ws.send(json.dumps({"subscribe": {"tags": [tag]}}))
        end = time.time() + seconds
        while time.time() < end:
            try:
                msg = json.loads(await asyncio.wait_for(ws.recv(), 1))
            except asyncio.TimeoutError:
                continue
            now = time.time()
            if msg.get("type") == "tags" and not msg.get("snapshot"):
                for v in msg.get("values", []):
                    out.append(now - v["timestamp"] / 1000)


def bench_reports(rate=5000, seconds=10):
    with tempfile.TemporaryDirectory() as tmp:
        plant = os.path.join(tmp, "plant")
        os.makedirs(plant)
        scl = os.path.join(plant, "TEST.scd")
        port, http = free_port(), free_port()
        peer = PeerIed(port, scl, tmp)
        subprocess.run([BIN, "scl", "import", scl, "--out", plant], check=True, capture_output=True, timeout=60)
        text = open(os.path.join(plant, "TEST.toml")).read()
        text = text.replace('dataset = "TESTLD0/LLN0.Events"', 'dataset = "TESTLD0/LLN0.Events"\nbuffer_time_ms = 0')
        open(os.path.join(plant, "TEST.toml"), "w").write(text)
        data = os.path.join(tmp, "data")
        proc = subprocess.Popen([BIN, "demo", "--config", plant, "--http", f"127.0.0.1:{http}", "--data", data,
                                 "--real-device", "TEST"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        client = None
        try:
            base = f"http://127.0.0.1:{http}"
            api, _ = login(base, data, proc)
            wait_for(lambda: (api.tag("TEST.Comm.Connected") or {}).get("value") is True, 30)
            jar = next(h for h in api.opener.handlers if hasattr(h, "cookiejar")).cookiejar
            cookie = "; ".join(f"{c.name}={c.value}" for c in jar)
            client = subprocess.Popen([sys.executable, "-c", PEER_CLIENT, str(port), str(seconds + 4)],
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            assert client.stdout.readline().startswith("READY")
            before = ((api.device("TEST")[0] or {}).get("telecontrol") or {}).get("events", 0)
            lat = []
            cpu0, client_cpu0 = cpu_s(proc.pid), cpu_s(client.pid)

            async def both():
                live = asyncio.create_task(live_latencies(base, cookie, "TEST.LD0.MMXU1.TotW", seconds + 3, lat))
                await asyncio.sleep(0.5)
                answer = await asyncio.to_thread(peer.cmd, {"burst": {"ref": "TESTLD0/MMXU1.TotW.mag.f",
                                                                      "count": rate * seconds, "rate": rate}}, seconds + 30)
                await live
                return answer
            answer = asyncio.run(both())
            cpu1, client_cpu1 = cpu_s(proc.pid), cpu_s(client.pid)
            time.sleep(1)
            after = ((api.device("TEST")[0] or {}).get("telecontrol") or {}).get("events", 0)
            out, err = client.communicate(timeout=60)
            m = re.search(r"RESULT (\d+) (\S+) (\S+)", out)
            lat.sort()
            p = lambda f: lat[min(len(lat) - 1, int(f * len(lat)))] * 1000 if lat else float("nan")
            sent = rate * seconds
            took = answer.get("seconds") or answer.get("elapsed") or seconds
            print(f"reports: the IED made {sent} changes ({json.dumps(answer)[:160]})")
            window = seconds + 3.5
            print(f"reports: gridscada took {after - before} report entries; /api/live pushed {len(lat)} values, "
                  f"latency IED t -> WebSocket p50 {p(0.5):.1f} ms, p99 {p(0.99):.1f} ms; "
                  f"{100 * (cpu1 - cpu0) / window:.1f} % of a core over the {window:.1f} s")
            if m:
                print(f"reports: open61850 client took {m.group(1)} entries, latency IED t -> handler p50 {m.group(2)} ms, "
                      f"p99 {m.group(3)} ms; {100 * (client_cpu1 - client_cpu0) / window:.1f} % of a core")
            else:
                print(f"reports: open61850 client gave no result: {out[-300:]} {err[-500:]}")
        finally:
            if client and client.poll() is None:
                client.kill()
            proc.terminate()
            proc.wait(10)
            peer.stop()


if __name__ == "__main__":
    which = sys.argv[1:] or ["import", "reports"]
    if "import" in which:
        bench_import()
    if "reports" in which:
        bench_reports()
