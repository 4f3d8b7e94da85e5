#!/usr/bin/env python3
"""IEC 61850: gridscada's MMS client, through the real binary, against
libiec61850's server, from the SCL file of that server's model.

- The test IED (tests/e2e/iec61850_peer.py, libiec61850 through
  pyiec61850-ng) serves one model and writes its SCL; `gridscada scl import`
  turns the SCL into a plant; `gridscada check` validates the tag file
  against the SCL and refuses a broken copy with the file, line and tag.
- gridscada (`demo --config`, the IED a real device) associates through a
  TCP proxy that this test can cut: every imported attribute reads equal
  to the server's value; changes reach /api/tags by report with the IED's
  own timestamp and quality; the connection is cut while the IED changes a
  value three times, and after the reconnect the buffered report is resumed
  by EntryID: all three changes are in the historian, none lost.
- Controls under each control model (SBO and direct, normal and enhanced
  security), with the user as originator, confirmed by the status; a
  refused select and a refused operate (interlock), with AddCause 10 in the
  failed write and the event log.
- open61850 (pure Python, independent) reads the same attributes: they
  agree with gridscada's.
- A hostile server completes the association and then answers with
  malformed PDUs: each association is dropped and counted, the good IED
  is unaffected, nothing panics.
- tshark dissects the capture (TPKT/COTP/session/presentation/MMS) with no
  malformed packet, and shows the LastApplError with AddCause 10.

Usage: iec61850_test.py GRIDSCADA_BINARY
"""

import json
import os
import queue
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import http.cookiejar
import urllib.error
import urllib.request

import checks
from checks import Api, check, free_port, login, note, wait_for

BIN = sys.argv[1] if len(sys.argv) > 1 else "target/debug/gridscada"
HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
STARTED = time.time()
LD = "TESTLD0"


def die_with_parent():
    try:
        import ctypes
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)
    except Exception:
        pass


class PeerIed:
    """The libiec61850 test IED, driven by JSON lines on stdin."""

    def __init__(self, port, scl, tmp):
        self.port = port
        self.err = open(os.path.join(tmp, "peer.err"), "w")
        self.proc = subprocess.Popen(
            [sys.executable, os.path.join(HERE, "iec61850_peer.py"), "--port", str(port), "--scl", scl],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self.err, text=True, bufsize=1,
            preexec_fn=die_with_parent)
        self.lines = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()
        ready = self._next(30)
        if not (ready or {}).get("ready"):
            raise RuntimeError(f"the test IED did not start: {ready}")

    def _read(self):
        for line in self.proc.stdout:
            self.lines.put(line)

    def _next(self, timeout):
        try:
            return json.loads(self.lines.get(timeout=timeout))
        except (queue.Empty, ValueError):
            return None

    def cmd(self, obj, timeout=30):
        self.proc.stdin.write(json.dumps(obj) + "\n")
        self.proc.stdin.flush()
        return self._next(timeout) or {}

    def stop(self):
        try:
            self.cmd({"quit": True}, timeout=5)
        except OSError:
            pass
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


class Proxy:
    """A TCP relay to the IED that the test can cut (connections closed,
    new ones refused) and put back, the way a station bus link fails."""

    def __init__(self, target_port):
        self.target = target_port
        self.port = free_port()
        self.conns = []
        self.lock = threading.Lock()
        self.listener = None
        self.restore()

    def restore(self):
        self.listener = socket.socket()
        self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.listener.bind(("127.0.0.1", self.port))
        self.listener.listen(8)
        threading.Thread(target=self._accept, args=(self.listener,), daemon=True).start()

    def _accept(self, listener):
        while True:
            try:
                client, _ = listener.accept()
            except OSError:
                return
            try:
                server = socket.create_connection(("127.0.0.1", self.target), timeout=5)
            except OSError:
                client.close()
                continue
            with self.lock:
                self.conns += [client, server]
            for a, b in ((client, server), (server, client)):
                threading.Thread(target=self._pump, args=(a, b), daemon=True).start()

    def _pump(self, a, b):
        try:
            while True:
                data = a.recv(65536)
                if not data:
                    break
                b.sendall(data)
        except OSError:
            pass
        for s in (a, b):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def cut(self):
        # shutdown wakes the thread blocked in accept(); close alone does not.
        try:
            self.listener.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.listener.close()
        with self.lock:
            for s in self.conns:
                try:
                    s.shutdown(socket.SHUT_RDWR)
                    s.close()
                except OSError:
                    pass
            self.conns = []


def load_fixture(name):
    """The server's TPKT packets ('<' lines) of a wire fixture."""
    path = os.path.join(ROOT, "server", "iec61850", "tests", "fixtures", name)
    return [bytes.fromhex(l[2:].strip()) for l in open(path) if l.startswith("< ")]


def tpkt_dt(payload):
    """One TPKT + COTP DT (last unit) around `payload`."""
    body = bytes([2, 0xF0, 0x80]) + payload
    return bytes([3, 0]) + (len(body) + 4).to_bytes(2, "big") + body


def mms_in_session(mms):
    """An MMS PDU in session give-tokens/DT and presentation user data."""
    def tlv(tag, content):
        n = len(content)
        head = bytes([n]) if n < 128 else bytes([0x82]) + n.to_bytes(2, "big")
        return bytes([tag]) + head + content
    pdv = tlv(0x30, bytes([2, 1, 3]) + tlv(0xA0, mms))
    return bytes([1, 0, 1, 0]) + tlv(0x61, pdv)


class Hostile:
    """A server that completes the association with libiec61850's own
    answers, then answers the first request with a malformed PDU, a
    different one on each connection."""

    CASES = [
        ("a read response whose length claims more than it holds",
         bytes([0xA1, 0x0A, 0x02, 0x01, 0x01, 0xA4, 0x05, 0xA1, 0x7F, 0x87, 0x05, 0x08])),
        ("a structure nested 200 deep", None),
        ("a floating-point of 3 octets",
         bytes([0xA1, 0x0C, 0x02, 0x01, 0x01, 0xA4, 0x07, 0xA1, 0x05, 0x87, 0x03, 0x08, 0x00, 0x00])),
        ("an unknown session SPDU", b"garbage"),
        ("a TPKT of version 9", b"version"),
    ]

    def __init__(self):
        accept = load_fixture("associate.hex")
        self.cc, self.ac = accept[0], accept[1]
        self.port = free_port()
        self.connections = 0
        self.sock = socket.socket()
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind(("127.0.0.1", self.port))
        self.sock.listen(4)
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                c, _ = self.sock.accept()
            except OSError:
                return
            case = self.CASES[self.connections % len(self.CASES)]
            self.connections += 1
            threading.Thread(target=self._talk, args=(c, case), daemon=True).start()

    @staticmethod
    def _packet(c):
        head = b""
        while len(head) < 4:
            d = c.recv(4 - len(head))
            if not d:
                return None
            head += d
        n = int.from_bytes(head[2:4], "big")
        body = b""
        while len(body) < n - 4:
            d = c.recv(n - 4 - len(body))
            if not d:
                return None
            body += d
        return head + body

    def _talk(self, c, case):
        c.settimeout(10)
        try:
            if self._packet(c) is None:
                return
            c.sendall(self.cc)
            if self._packet(c) is None:
                return
            c.sendall(self.ac)
            if self._packet(c) is None:
                return
            what, pdu = case
            if pdu is None:
                deep = bytes([0x83, 1, 0])
                for _ in range(200):
                    deep = bytes([0xA2]) + (bytes([len(deep)]) if len(deep) < 128 else bytes([0x82]) + len(deep).to_bytes(2, "big")) + deep
                inner = bytes([0xA1]) + bytes([0x82]) + len(deep).to_bytes(2, "big") + deep
                body = bytes([0x02, 0x01, 0x01, 0xA4]) + bytes([0x82]) + len(inner).to_bytes(2, "big") + inner
                pdu = bytes([0xA1, 0x82]) + len(body).to_bytes(2, "big") + body
            if pdu == b"garbage":
                c.sendall(tpkt_dt(bytes([0x77, 0x03, 1, 2, 3])))
            elif pdu == b"version":
                c.sendall(bytes([9, 0, 0, 8, 1, 2, 3, 4]))
            else:
                c.sendall(tpkt_dt(mms_in_session(pdu)))
            time.sleep(2)
        except OSError:
            pass
        finally:
            c.close()

    def close(self):
        self.sock.close()


def tag_files(plant):
    """The imported tags: name -> (ref, type, writable, ctl_model)."""
    import tomllib
    out = {}
    with open(os.path.join(plant, "TEST.toml"), "rb") as f:
        doc = tomllib.load(f)
    for t in doc.get("tag", []):
        p = t["iec61850"]
        out[t["name"]] = (p["ref"], t.get("type"), t.get("writable", False), p.get("ctl_model"))
    return doc, out


def same(peer_value, api_value, ty, ref=""):
    if peer_value is None or api_value is None:
        return False
    if ty == "bool" and ref.endswith("Pos.stVal"):
        # A switch position (Dbpos: 1 off, 2 on) on a bool tag.
        return {1: False, 2: True}.get(int(peer_value)) == api_value
    if ty in ("f32", "f64"):
        return abs(float(peer_value) - float(api_value)) <= 1e-3 * max(1.0, abs(float(peer_value)))
    if ty == "bool":
        return bool(peer_value) == api_value
    return int(peer_value) == int(api_value)


def main():
    tmp = tempfile.mkdtemp(prefix="gridscada-iec61850-")
    plant = os.path.join(tmp, "plant")
    os.makedirs(plant)
    scl = os.path.join(plant, "TEST.scd")
    ied_port, http_port = free_port(), free_port()
    peer = PeerIed(ied_port, scl, tmp)
    proxy = Proxy(ied_port)
    hostile = Hostile()
    cap = os.path.join(tmp, "iec61850.pcapng")
    tshark = subprocess.Popen(
        ["tshark", "-q", "-i", "lo", "-f", f"tcp port {ied_port} or tcp port {proxy.port} or tcp port {hostile.port}",
         "-w", cap], stdout=subprocess.DEVNULL, stderr=open(os.path.join(tmp, "tshark.log"), "w"),
        preexec_fn=die_with_parent)
    wait_for(lambda: os.path.exists(cap), 10)
    time.sleep(1)
    proc = None
    log_path = os.path.join(tmp, "server.log")
    try:
        # The substation's single-line part: two bays whose functions sit
        # on the IED's logical nodes (the test IED's SCL has none).
        text = open(scl).read()
        bays = ('<Substation name="S1"><VoltageLevel name="D1"><Bay name="Q1 Feeder">'
                '<ConductingEquipment name="QA1" type="CBR"><LNode iedName="TEST" ldInst="LD0" lnClass="CSWI" lnInst="1"/>'
                '</ConductingEquipment><LNode iedName="TEST" ldInst="LD0" lnClass="MMXU" lnInst="1"/></Bay>'
                '<Bay name="Q2"><LNode iedName="TEST" ldInst="LD0" lnClass="CSWI" lnInst="2"/>'
                '<LNode iedName="TEST" ldInst="LD0" lnClass="GGIO" lnInst="1"/></Bay></VoltageLevel></Substation>')
        open(scl, "w").write(text.replace("<Communication>", bays + "<Communication>", 1))
        r = subprocess.run([BIN, "scl", "import", scl, "--out", plant, "--screens", "--address", f"TEST=127.0.0.1:{proxy.port}"],
                           capture_output=True, text=True, timeout=60)
        check(r.returncode == 0 and os.path.exists(os.path.join(plant, "TEST.toml")),
              "gridscada scl import writes a tag file and a main file from the IED's SCL", r.stdout + r.stderr)
        note(r.stdout.strip().splitlines()[0] if r.stdout.strip() else "no output")
        doc, tags = tag_files(plant)
        screens = sorted(os.listdir(os.path.join(plant, "screens"))) if os.path.isdir(os.path.join(plant, "screens")) else []
        q1 = json.load(open(os.path.join(plant, "screens", "s1-d1-q1-feeder.json"))) if "s1-d1-q1-feeder.json" in screens else {}
        kinds_on_q1 = sorted({(e["type"], e.get("tag", "")) for e in q1.get("elements", []) if e["type"] != "text"})
        check(screens == ["s1-d1-q1-feeder.json", "s1-d1-q2.json"]
              and ("breaker", "TEST.LD0.CSWI1.Pos") in kinds_on_q1 and ("button", "TEST.LD0.CSWI1.Pos") in kinds_on_q1
              and ("value", "TEST.LD0.MMXU1.TotW") in kinds_on_q1 and not any("CSWI2" in t for _, t in kinds_on_q1),
              "scl import --screens draws a screen per bay: its breaker with Open and Close, its measurands",
              f"{screens} {kinds_on_q1}")
        kinds = {ty for _, ty, _, _ in tags.values()}
        check(len(tags) >= 15 and {"bool", "f32", "i64", "i32"} <= kinds
              and sum(1 for v in tags.values() if v[2]) == 5,
              "the import has the statuses, switch positions, measurands, counter and the 5 controllable objects",
              json.dumps(tags, indent=1)[:2000])
        units = {t["name"]: t.get("units") for t in doc["tag"]}
        check(units.get("TEST.LD0.MMXU1.TotW") == "W" and units.get("TEST.LD0.MMXU1.PhV.phsA") == "kV"
              and units.get("TEST.LD0.MMTR1.TotWh") == "kWh",
              "units come from the SCL's SIUnit and multiplier (W, kV, kWh)", str(units))
        models = {n: v[3] for n, v in tags.items() if v[2]}
        check(models.get("TEST.LD0.CSWI1.Pos") == "sbo-with-enhanced-security"
              and models.get("TEST.LD0.CSWI2.Pos") == "direct-with-normal-security",
              "control models come from the SCL's ctlModel", str(models))
        # The hostile server, as a second device of the same plant.
        with open(os.path.join(plant, "hostile.toml"), "w") as f:
            f.write(f'[[device]]\nname = "HOSTILE"\nprotocol = "iec61850"\naddress = "127.0.0.1:{hostile.port}"\n'
                    f'backoff_max_ms = 500\n\n[[tag]]\nname = "HOSTILE.Ind"\ndevice = "HOSTILE"\ntype = "bool"\n'
                    f'iec61850 = {{ ref = "TESTLD0/GGIO1.Ind1.stVal", fc = "ST" }}\n')
        # A second association with the same IED on its unbuffered RCB.
        with open(os.path.join(plant, "urcb.toml"), "w") as f:
            f.write(f'[[device]]\nname = "TEST_U"\nprotocol = "iec61850"\naddress = "127.0.0.1:{proxy.port}"\n\n'
                    f'[[device.iec61850.report]]\nrcb = "TESTLD0/LLN0.RP.urcb01"\ndataset = "TESTLD0/LLN0.Events"\n\n'
                    f'[[tag]]\nname = "TEST_U.Ind1"\ndevice = "TEST_U"\ntype = "bool"\n'
                    f'iec61850 = {{ ref = "TESTLD0/GGIO1.Ind1.stVal", fc = "ST" }}\n')
        # The operator asks the IED to check interlocks on CSWI4.
        t = open(os.path.join(plant, "TEST.toml")).read()
        t = t.replace('control = "TESTLD0/CSWI4.Pos", ctl_model = "direct-with-enhanced-security" }',
                      'control = "TESTLD0/CSWI4.Pos", ctl_model = "direct-with-enhanced-security", interlock_check = true }')
        open(os.path.join(plant, "TEST.toml"), "w").write(t)
        main_file = os.path.join(plant, "gridscada.toml")
        text = open(main_file).read().replace('tag_files = ["TEST.toml"]', 'tag_files = ["TEST.toml", "hostile.toml", "urcb.toml"]')
        open(main_file, "w").write(text)
        r = subprocess.run([BIN, "check", plant], capture_output=True, text=True, timeout=60)
        check(r.returncode == 0, "gridscada check validates the imported tags against the SCL", r.stdout + r.stderr)
        # A broken copy: a reference the IED does not have, a wrong type.
        bad = os.path.join(tmp, "bad")
        shutil.copytree(plant, bad)
        t = open(os.path.join(bad, "TEST.toml")).read()
        t = t.replace('scl = "TEST.scd"', f'scl = "{scl}"')
        t = t.replace('TESTLD0/GGIO1.AnIn1.mag.f"', 'TESTLD0/GGIO1.AnIn9.mag.f"', 1)
        t = t.replace('type = "bool"\niec61850 = { ref = "TESTLD0/GGIO1.Ind1.stVal"',
                      'type = "string"\niec61850 = { ref = "TESTLD0/GGIO1.Ind1.stVal"', 1)
        open(os.path.join(bad, "TEST.toml"), "w").write(t)
        r = subprocess.run([BIN, "check", bad], capture_output=True, text=True, timeout=60)
        out = r.stdout + r.stderr
        check(r.returncode != 0 and "TEST.toml:" in out and "AnIn9" in out and "TEST.LD0.GGIO1.Ind1" in out
              and "BOOLEAN" in out,
              "gridscada check refuses tags that do not match the SCL, with file, line and tag", out[-1500:])

        data = os.path.join(tmp, "data")
        log = open(log_path, "w")
        proc = subprocess.Popen([BIN, "demo", "--config", plant, "--http", f"127.0.0.1:{http_port}", "--data", data,
                                 "--real-device", "TEST", "--real-device", "HOSTILE", "--real-device", "TEST_U"],
                                stdout=log, stderr=subprocess.STDOUT, preexec_fn=die_with_parent)
        run(f"http://127.0.0.1:{http_port}", data, proc, peer, proxy, hostile, tags, ied_port)
    except Exception as e:
        import traceback
        check(False, "the test ran to its end", f"{e!r}\n{traceback.format_exc()}")
    finally:
        if proc is not None:
            check(proc.poll() is None, "gridscada is still running at the end", f"exit code {proc.poll()}")
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
        peer.stop()
        proxy.cut()
        hostile.close()
        time.sleep(1)
        tshark.terminate()
        try:
            tshark.wait(10)
        except subprocess.TimeoutExpired:
            tshark.kill()
        wire_check(cap, ied_port, proxy.port)
        if checks.FAILED:
            print("--- server log (last 60 lines) ---")
            try:
                print("".join(open(log_path).readlines()[-60:]))
            except OSError:
                pass
            print(f"(everything is in {tmp})")
        elif os.environ.get("KEEP_TMP"):
            print(f"(kept: {tmp})")
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    print(f"{checks.PASSED} passed, {checks.FAILED} failed ({time.time() - STARTED:.0f} s)")
    sys.exit(1 if checks.FAILED else 0)


def run(base, data, proc, peer, proxy, hostile, tags, ied_port):
    api, user = login(base, data, proc)
    check(api is not None, "gridscada demo --config serves the imported plant and logs in")
    if api is None:
        return
    st, listed = api.call("GET", "/api/screens")
    check(st == 200 and "s1-d1-q1-feeder" in json.dumps(listed) and "S1 / D1 / Q2" in json.dumps(listed),
          "the bay screens are on the HMI's screen list", json.dumps(listed)[:500])
    connected = wait_for(lambda: (api.tag("TEST.Comm.Connected") or {}).get("value") is True, 30)
    check(connected, "gridscada associates with the IED", json.dumps(api.tag("TEST.Comm.LastError")))

    # -- Every imported attribute reads equal to the server's value.
    values = peer.cmd({"values": True}).get("values", {})
    def all_equal():
        wrong = []
        for name, (ref, ty, _, _) in tags.items():
            t = api.tag(name) or {}
            v = values.get(ref, {}).get("value")
            if (t.get("quality") or {}).get("code") != "good" or not same(v, t.get("value"), ty, ref):
                wrong.append(f"{name}: IED {v!r}, gridscada {t.get('value')!r} {json.dumps(t.get('quality'))}")
        return wrong
    wrong = wait_for(lambda: not all_equal() or None, 20) and [] or all_equal()
    check(not wrong, f"all {len(tags)} imported attributes read Good and equal to the IED's values", "\n".join(wrong[:10]))

    # -- A change reaches /api/tags by report, with the IED's timestamp.
    stamp = round(time.time() - 3600, 3)
    ans = peer.cmd({"set": f"{LD}/GGIO1.Ind1.stVal", "value": True, "t": stamp})
    got = wait_for(lambda: (lambda t: t if t and t.get("value") is True else None)(api.tag("TEST.LD0.GGIO1.Ind1")), 10)
    check(got and abs(got.get("timestamp", 0) - stamp * 1000) <= 1,
          "a status change reaches /api/tags by report with the IED's own timestamp (an hour ago)",
          f"{ans} -> {json.dumps(got)}")
    got = wait_for(lambda: (lambda t: t if t and t.get("value") is True else None)(api.tag("TEST_U.Ind1")), 10)
    check(got and abs(got.get("timestamp", 0) - stamp * 1000) <= 1,
          "the same change reaches a second association by the unbuffered RCB (reserved, enabled)", json.dumps(got))
    stamp2 = round(time.time() - 60, 3)
    peer.cmd({"set": f"{LD}/MMXU1.TotW.mag.f", "value": 4321.5, "t": stamp2})
    got = wait_for(lambda: (lambda t: t if t and abs((t.get("value") or 0) - 4321.5) < 0.01 else None)(
        api.tag("TEST.LD0.MMXU1.TotW")), 10)
    check(got and abs(got.get("timestamp", 0) - stamp2 * 1000) <= 1,
          "a measurand change arrives by report with its timestamp", json.dumps(got))
    # Quality: questionable + oldData (bits 0,1 and 7 -> 3 + 128).
    peer.cmd({"set": f"{LD}/MMXU1.TotW.mag.f", "value": 4322.0, "q": 131})
    got = wait_for(lambda: (lambda t: t if t and (t.get("quality") or {}).get("code") == "uncertain" else None)(
        api.tag("TEST.LD0.MMXU1.TotW")), 10)
    check(got and "questionable" in json.dumps(got) and "old data" in json.dumps(got),
          "the IED's quality (questionable, old data) is the tag's, in words", json.dumps(got))
    peer.cmd({"set": f"{LD}/MMXU1.TotW.mag.f", "value": 4323.0, "q": 0})

    # -- The link is cut; the IED changes a value three times; after the
    # reconnect the buffered report resumes by EntryID: nothing lost.
    time.sleep(1.5)
    proxy.cut()
    lost = wait_for(lambda: (api.tag("TEST.Comm.Connected") or {}).get("value") is False, 15)
    check(lost, "a cut link shows: Comm.Connected false")
    bad = wait_for(lambda: (lambda t: t if t and (t.get("quality") or {}).get("code") == "bad" else None)(
        api.tag("TEST.LD0.GGIO1.Ind1")), 10)
    check(bad and "communication lost" in json.dumps(bad), "the IED's tags turn Bad with the reason", json.dumps(bad))
    t0 = time.time()
    stamps = []
    for i, v in enumerate([False, True, False]):
        s = round(t0 - 30 + i, 3)
        stamps.append(s)
        peer.cmd({"set": f"{LD}/GGIO1.Ind1.stVal", "value": v, "t": s})
        time.sleep(0.3)
    time.sleep(1)
    proxy.restore()
    back = wait_for(lambda: (api.tag("TEST.Comm.Connected") or {}).get("value") is True, 30)
    check(back, "the link put back, gridscada associates again")
    final = wait_for(lambda: (lambda t: t if t and t.get("value") is False and
                              (t.get("quality") or {}).get("code") == "good" else None)(api.tag("TEST.LD0.GGIO1.Ind1")), 15)
    check(final and abs(final.get("timestamp", 0) - stamps[-1] * 1000) <= 1,
          "after the reconnect the tag shows the last change, with its time", json.dumps(final))
    def history():
        st, body = api.call("GET", f"/api/trends.csv?tags=TEST.LD0.GGIO1.Ind1&from={int(t0 * 1000) - 60000}&to={int(t0 * 1000) + 60000}")
        return body if st == 200 and isinstance(body, str) else ""
    def has_all():
        h = history()
        return all(str(int(round(s * 1000))) in h or time.strftime("%H:%M:%S", time.gmtime(s)) in h for s in stamps)
    ok = wait_for(has_all, 30, 1)
    check(ok, "the buffered report was resumed by EntryID: all three changes made while cut are in the historian",
          history()[-1500:])

    # -- Controls, each model; the user is the originator.
    def write(name, value):
        return api.call("POST", f"/api/tags/{name}/write", {"value": value}, timeout=60)
    for name, model in [("TEST.LD0.CSWI1.Pos", "sbo-with-enhanced-security"), ("TEST.LD0.CSWI2.Pos", "direct-with-normal-security"),
                        ("TEST.LD0.CSWI3.Pos", "sbo-with-normal-security"), ("TEST.LD0.CSWI4.Pos", "direct-with-enhanced-security")]:
        status, body = write(name, True)
        now = api.tag(name) or {}
        check(status == 200 and now.get("value") is True, f"{model}: close is operated and confirmed by the status",
              f"{status} {json.dumps(body)} {json.dumps(now)}")
    status, body = write("TEST.LD0.GGIO1.SPCSO1", True)
    check(status == 200, "direct-with-normal-security on an SPC: on", f"{status} {json.dumps(body)}")
    actions = peer.cmd({"controls": True}).get("controls", [])
    cswi1 = [a for a in actions if a.get("ref") == f"{LD}/CSWI1.Pos" and a.get("action") in ("select", "operate")]
    check([a.get("action") for a in cswi1][:2] == ["select", "operate"] and all(a.get("orIdent") == user for a in cswi1)
          and all(a.get("orCat") == 3 for a in cswi1) and len({a.get("ctlNum") for a in cswi1[:2]}) == 1,
          "SBOw then Oper, with the user as orIdent, remote-control as orCat and one ctlNum", json.dumps(cswi1))
    cswi4 = [a for a in actions if a.get("ref") == f"{LD}/CSWI4.Pos" and a.get("action") == "operate"]
    check(cswi4 and cswi4[-1].get("interlock_check") is True and cswi1 and cswi1[-1].get("interlock_check") is False,
          "the Check bits go as configured: interlock check on CSWI4, not on CSWI1", json.dumps(cswi4 + cswi1[-1:]))
    # Interlock: the IED refuses "close"; the write fails with the cause.
    status, _ = write("TEST.LD0.CSWI1.Pos", False)
    check(status == 200 and (api.tag("TEST.LD0.CSWI1.Pos") or {}).get("value") is False,
          "open under sbo-with-enhanced-security", str(status))
    peer.cmd({"interlock": True})
    status, body = write("TEST.LD0.CSWI1.Pos", True)
    text = json.dumps(body)
    check(status != 200 and "select" in text and "blocked by interlocking (AddCause 10)" in text,
          "a refused select (interlock) fails the write naming AddCause 10", f"{status} {text}")
    write("TEST.LD0.CSWI2.Pos", False)
    status, body = write("TEST.LD0.CSWI2.Pos", True)
    text = json.dumps(body)
    check(status != 200 and "operate" in text and "blocked by interlocking (AddCause 10)" in text,
          "a refused operate (interlock, direct control) fails the write naming AddCause 10", f"{status} {text}")
    peer.cmd({"interlock": False})
    st, ev = api.call("GET", "/api/events?limit=100")
    events = json.dumps(ev)
    check(st == 200 and "AddCause 10" in events and "TEST.LD0.CSWI1.Pos" in events,
          "the refused controls are in the event log with their cause")

    # -- An independent client agrees with gridscada.
    refs = [f"{ref}[{'MX' if ty in ('f32', 'f64') and '.mag.' in ref else 'ST'}]" for ref, ty, _, _ in tags.values()]
    r = subprocess.run([sys.executable, os.path.join(HERE, "iec61850_xcheck.py"), "--port", str(ied_port), "--refs", *refs],
                       capture_output=True, text=True, timeout=60)
    try:
        theirs = json.loads(r.stdout)
    except ValueError:
        theirs = {}
    disagree = []
    for name, (ref, ty, _, _) in tags.items():
        key = next((k for k in theirs if k.startswith(ref + "[") or k == ref), None)
        t = api.tag(name) or {}
        v = theirs.get(key) if key else None
        if isinstance(v, dict):
            v = v.get("value")
        if not same(v, t.get("value"), ty, ref):
            disagree.append(f"{name}: open61850 {v!r}, gridscada {t.get('value')!r}")
    check(theirs and not disagree, f"open61850 reads the same {len(tags)} attributes as gridscada",
          "\n".join(disagree[:10]) + r.stderr[-500:])

    # -- The hostile server: each malformed answer drops and counts its
    # association; the good IED stays Good; nothing panics.
    wait_for(lambda: hostile.connections >= len(Hostile.CASES) + 1, 30, 0.5)
    dev, link = api.device("HOSTILE")
    check(hostile.connections >= len(Hostile.CASES) and (link or {}).get("garbage_bytes", 0) >= 3
          and (link or {}).get("disconnects", 0) >= len(Hostile.CASES),
          "a hostile IED's malformed PDUs each drop its association and are counted",
          f"{hostile.connections} connections, {json.dumps(link)}")
    good = api.tag("TEST.LD0.GGIO1.AnIn1") or {}
    check((good.get("quality") or {}).get("code") == "good" and api.healthz() == 200,
          "the good IED is unaffected by the hostile one", json.dumps(good))


def wire_check(cap, ied_port, proxy_port):
    decode = ["-d", f"tcp.port=={ied_port},tpkt", "-d", f"tcp.port=={proxy_port},tpkt"]
    count = subprocess.run(["tshark", "-r", cap, *decode, "-Y", "mms"], capture_output=True, text=True, timeout=120)
    packets = len(count.stdout.splitlines())
    bad = subprocess.run(["tshark", "-r", cap, *decode, "-Y",
                          f"(tcp.port == {ied_port}) && (_ws.malformed || _ws.expert.severity >= error)"],
                         capture_output=True, text=True, timeout=120)
    lines = bad.stdout.splitlines()
    check(packets > 50 and not lines and bad.returncode == 0,
          f"tshark dissects the session's {packets} MMS packets with no malformed or expert-error packet",
          "\n".join(lines[:10]) + bad.stderr[-300:])
    w = subprocess.run(["tshark", "-r", cap, *decode, "-Y", f"mms.confirmedServiceRequest == 5 && tcp.dstport == {ied_port}",
                        "-T", "fields", "-e", "frame.number", "-e", "mms.itemId"], capture_output=True, text=True, timeout=120).stdout
    writes = [l.split("\t") for l in w.splitlines()]
    entry = [f for f, i in writes if i.endswith("$EntryID")]
    enable = [f for f, i in writes if i.endswith("brcb01$RptEna")]
    check(entry and any(int(e) > int(entry[0]) for e in enable) and all("$EntryID" not in i for f, i in writes[:8]),
          "tshark: after the reconnect gridscada wrote the BRCB's EntryID, then enabled it (the resume)",
          f"EntryID writes at {entry}, RptEna writes at {enable}")
    check(any(i.endswith("urcb01$Resv") for f, i in writes) and any(i.endswith("urcb01$RptEna") for f, i in writes),
          "tshark: the unbuffered RCB was reserved (Resv) before it was enabled")
    v = subprocess.run(["tshark", "-r", cap, *decode, "-Y", f"mms && tcp.srcport == {ied_port}", "-V"],
                       capture_output=True, text=True, timeout=120).stdout
    check("LastApplError" in v and "integer: 10" in v,
          "tshark: the IED sent LastApplError with AddCause 10, the cause gridscada named")


if __name__ == "__main__":
    main()
