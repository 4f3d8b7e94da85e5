#!/usr/bin/env python3
"""DNP3: gridscada's master, through the real binary, against two
independent Python outstations, with a tshark wire check and hostile
outstations.

gridscada runs `demo --config` on a plant of three DNP3 devices:

- OS1, dnp3py 0.6.0's outstation (event polls every second, no unsolicited
  responses: its TCP runner sends none): binary inputs, an analog input, a
  counter whose events carry the outstation's time (g22v5), a breaker
  (binary output status + CROB with select-before-operate), a pump whose
  direct-operate CROB is refused (HARDWARE_ERROR), an analog output with
  engineering limits (g41, direct operate); it is stopped and started again
  (IIN1.7 device restart);
- OS2, py1815 0.3.0's outstation (unsolicited responses only, no event
  polls): a double-bit input (g3v2, encoded here: py1815 has no encoder for
  it), binary inputs and an analog input whose events come unsolicited with
  the outstation's time (g2v2, g32v3), a counter, binary outputs
  (g10v2 + CROB, one of them refused NOT_AUTHORIZED), an analog output
  (g40 + g41);
- OS3, a second dnp3py outstation reached over a serial line: gridscada
  opens a pseudo-terminal that socat joins to the outstation's TCP port
  (the way an RS-232 RTU sits behind a terminal server); values, a
  select-before-operate CROB, and the line pulled and put back;
- HB, a hostile outstation written here: it answers gridscada's requests
  with (a) link frames whose user data CRC is wrong, (b1) a transport
  segment with FIR and no FIN that is never continued, (b2) an object header
  claiming more objects than the fragment holds, (c) garbage octets; then
  correct answers again. See hostile_cases for what gridscada does with
  each, and what is left unchecked as a product bug.

The checks read what reaches gridscada's API (values, quality, timestamps,
the audited write, the event log, the devices API, /metrics), what the
outstations saw (their own log lines), and tshark's DNP3 dissector on a
capture of lo.

Usage: dnp3_test.py GRIDSCADA_BINARY
Prints one line per check and "N passed, M failed" last; exits 1 on failure.
"""

import json
import os
import queue
import random
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

import checks
from checks import Api, check, free_port, login, note, wait_for
import http.cookiejar
import urllib.error
import urllib.request

try:
    import dnp3  # noqa: F401  (the outstation processes import it)
    import py1815  # noqa: F401
except ImportError as e:  # the README test command installs them
    print(f"FAIL setup: dnp3py or py1815 is not importable ({e}); pip install -r tests/requirements.txt")
    print("0 passed, 1 failed")
    sys.exit(1)

BIN = sys.argv[1]
STARTED = time.time()






def die_with_parent():
    """For Popen's preexec_fn: the child gets SIGTERM when this test dies,
    however it dies (Linux)."""
    try:
        import ctypes
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except Exception:
        pass






# ---------------------------------------------------------------------------
# The outstations: each a process of its own (asyncio servers; killing one is
# the outstation's restart), driven through stdin, saying what it saw on
# stdout.

DNP3PY = r'''
import asyncio, os, sys
from dnp3.core.timestamp import DNP3Timestamp
from dnp3.database import AnalogInputConfig, BinaryInputConfig, BinaryOutputConfig, Database, EventClass
from dnp3.outstation import Outstation, OutstationConfig, OutstationTcpRunner
from dnp3.outstation.handler import CommandResult

def say(*a):
    print(*a, flush=True)

db = Database()

class Handler:
    # Output 0 (the breaker) is selected and operated; its position is
    # binary input 2, which follows. Analog output 0 takes any value, and
    # analog input 1 returns it. (The returned status confirms a command.)
    def select_binary_output(self, index, code, count, on_time, off_time, *a, **k):
        say("SELECT", index, int(code))
        return CommandResult.success()
    def operate_binary_output(self, index, code, count, on_time, off_time, *a, **k):
        say("OPERATE", index, int(code))
        db.update_binary_output(index, value=int(code) == 3)
        if index == 0:
            db.update_binary_input(2, value=int(code) == 3)
        return CommandResult.success()
    def direct_operate_binary_output(self, index, code, count, on_time, off_time, *a, **k):
        # Output 1 (a pump) has failed: refused.
        say("DIRECT", index, int(code))
        return CommandResult.hardware_error() if index == 1 else CommandResult.success()
    def select_analog_output(self, index, value, *a, **k):
        say("SELECT_AO", index, value)
        return CommandResult.success()
    def operate_analog_output(self, index, value, *a, **k):
        say("OPERATE_AO", index, value)
        return CommandResult.success()
    def direct_operate_analog_output(self, index, value, *a, **k):
        say("DIRECT_AO", index, value)
        db.update_analog_output(index, value=value)
        db.update_analog_input(1, value=value)
        return CommandResult.success()

async def commands():
    loop = asyncio.get_running_loop()
    while True:
        line = await loop.run_in_executor(None, sys.stdin.readline)
        if not line:  # the test is gone
            os._exit(0)
        w = line.split()
        if w[0] == "COUNTER":
            db.update_counter(0, value=int(w[1]), timestamp=DNP3Timestamp(int(w[2])))
            say("COUNTER", w[1], w[2])
        elif w[0] == "ANALOG":
            db.update_analog_input(0, value=float(w[1]))
            say("ANALOG", w[1])
        elif w[0] == "BINARY":
            db.update_binary_input(int(w[1]), value=w[2] == "1")
            say("BINARY", w[1], w[2])

async def main(port):
    for i in range(3):
        db.add_binary_input(i, BinaryInputConfig())
    db.add_analog_input(0, AnalogInputConfig())
    db.add_analog_input(1, AnalogInputConfig())
    db.add_counter(0)
    # No events for the output: dnp3py 0.6.0 sends binary output events as
    # g2v1 (binary INPUT events) with the output's index, which would set
    # binary input 0.
    db.add_binary_output(0, BinaryOutputConfig(event_class=EventClass.NONE))
    db.add_binary_output(1, BinaryOutputConfig(event_class=EventClass.NONE))
    db.add_analog_output(0)
    db.update_binary_input(0, value=False)
    db.update_binary_input(1, value=True)
    db.update_binary_input(2, value=False)
    db.update_analog_input(0, value=42)
    db.update_analog_input(1, value=10)
    db.update_counter(0, value=7)
    db.update_binary_output(0, value=False)
    db.update_binary_output(1, value=False)
    db.update_analog_output(0, value=10)
    o = Outstation(database=db, config=OutstationConfig(address=1024, master_address=1),
                   handler=Handler())
    runner = OutstationTcpRunner(outstation=o, host="127.0.0.1", port=port)
    say("LISTENING")
    await asyncio.gather(runner.run(), commands())

asyncio.run(main(int(sys.argv[1])))
'''

PY1815 = r'''
import asyncio, sys, time
from py1815 import Session, OutstationServer
from py1815.control import CommandStatus, encode_binary_output_status, encode_analog_output_status
from py1815.events import EventBuffers, EventClass
from py1815.objects import AnalogPoint, BinaryPoint, CounterPoint, analog_range, binary_range, counter_range

def say(*a):
    print(*a, flush=True)

state = {"outputs": [False, False], "ao": 20.0, "dbi": 2}
EVENTS = EventBuffers()
SERVER = []

class Points:
    # Class 0: a double-bit input (g3v2: py1815 has no encoder for it, the
    # state is in the flag octet's top two bits, 1 off, 2 on), binary inputs
    # 0-1, analog input 0, counter 0, binary outputs 0-1 (g10v2), analog
    # output 0 (g40v1).
    def read(self, headers):
        if not any(h.group == 60 and h.variation == 1 for h in headers):
            return b""
        dbi = bytes([3, 2, 0, 0, 0, 0x01 | (state["dbi"] << 6)])
        bo = bytes([10, 2, 0, 0, 1]) + b"".join(
            encode_binary_output_status(state=s) for s in state["outputs"])
        ao = bytes([40, 1, 0, 0, 0]) + encode_analog_output_status(state["ao"], 1)
        # Binary input 2 is output 0's breaker position; analog input 1
        # returns analog output 0's value: they confirm the commands.
        return (dbi + binary_range(0, [BinaryPoint(False), BinaryPoint(False), BinaryPoint(state["outputs"][0])])
                + analog_range(0, [AnalogPoint(1234), AnalogPoint(state["ao"])])
                + counter_range(0, [CounterPoint(555)])
                + bo + ao)

class Controls:
    # Output 0 and analog output 0 may be operated; output 1 is refused.
    def answer(self, controls):
        return [CommandStatus.NOT_AUTHORIZED if (c.group == 12 and c.index == 1) else CommandStatus.SUCCESS
                for c in controls]
    def select(self, controls):
        say("SELECT", *[f"g{c.group}:{c.index}" for c in controls])
        return self.answer(controls)
    def operate(self, controls):
        say("OPERATE", *[f"g{c.group}:{c.index}" for c in controls])
        statuses = self.answer(controls)
        for c, st in zip(controls, statuses):
            if st != CommandStatus.SUCCESS or c.index != 0:
                continue
            if c.group == 12:
                on = (c.command.control_code & 0x0F) in (1, 3) or (c.command.control_code >> 6) == 1
                state["outputs"][0] = on
                EVENTS.record_binary(2, BinaryPoint(on), event_class=EventClass.CLASS_1)
            elif c.group == 41:
                state["ao"] = float(c.command.value)
                EVENTS.record_analog(1, AnalogPoint(state["ao"]), event_class=EventClass.CLASS_2)
        if SERVER:
            SERVER[0].notify()
        return statuses

async def main(port):
    events = EVENTS
    session = Session(Points(), control_provider=Controls(), events=events,
                      outstation_address=1024, master_address=1,
                      need_time=True, time_sink=lambda ms: say("TIME", ms), unsolicited=True)
    server = OutstationServer(session, bind=f"127.0.0.1:{port}")
    SERVER.append(server)
    await server.start()
    say("LISTENING")
    loop = asyncio.get_running_loop()
    while True:
        line = await loop.run_in_executor(None, sys.stdin.readline)
        if not line:
            return
        w = line.split()
        if w[0] == "EVENT":
            # Binary input 1 turns on, time-stamped by this outstation.
            stamp = int(w[1])
            events.record_binary(1, BinaryPoint(w[2] == "1"), event_class=EventClass.CLASS_1,
                                 timestamp_ms=stamp)
            say("EVENT", stamp)
            server.notify()
        elif w[0] == "ANALOG":
            events.record_analog(0, AnalogPoint(int(w[1])), event_class=EventClass.CLASS_2,
                                 timestamp_ms=int(w[2]))
            say("ANALOG", w[1], w[2])
            server.notify()

asyncio.run(main(int(sys.argv[1])))
'''


class Peer:
    """An outstation process: `send` a line to it, `said` what it said."""

    def __init__(self, name, script, port, tmp):
        self.name, self.port, self.tmp = name, port, tmp
        # Not "<name>.py": py1815.py would shadow the package it imports.
        self.path = os.path.join(tmp, f"outstation_{name}.py")
        with open(self.path, "w") as f:
            f.write(script)
        self.lines = []
        self.proc = None
        self.start()

    def start(self):
        self.err = open(os.path.join(self.tmp, f"{self.name}.stderr"), "a")
        self.proc = subprocess.Popen([sys.executable, self.path, str(self.port)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=self.err, text=True, bufsize=1,
                                     preexec_fn=die_with_parent)
        proc = self.proc

        def read():
            for line in proc.stdout:
                self.lines.append(line.strip())
        threading.Thread(target=read, daemon=True).start()
        wait_for(lambda: "LISTENING" in self.lines or proc.poll() is not None, 20)
        if "LISTENING" not in self.lines:
            raise RuntimeError(f"{self.name} did not start: {self.stderr_tail()}")

    def send(self, line):
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()

    def said(self, prefix):
        return [l for l in self.lines if l.startswith(prefix)]

    def stop(self):
        if self.proc and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)

    def stderr_tail(self):
        try:
            return "".join(open(os.path.join(self.tmp, f"{self.name}.stderr")).readlines()[-15:])
        except OSError:
            return ""


# ---------------------------------------------------------------------------
# The hostile outstation: link frames built here (CRC included), answering
# every request gridscada sends (everything but a CONFIRM) as `mode` says.

def crc(data):
    c = 0
    for b in data:
        c ^= b
        for _ in range(8):
            c = (c >> 1) ^ 0xA6BC if c & 1 else c >> 1
    return (~c) & 0xFFFF


def link_frame(user_data, src=1024, dst=1, corrupt=False):
    """An UNCONFIRMED_USER_DATA frame from the outstation; `corrupt` makes the
    last user data block's CRC wrong."""
    head = bytes([0x05, 0x64, 5 + len(user_data), 0x44]) + dst.to_bytes(2, "little") + src.to_bytes(2, "little")
    out = head + crc(head).to_bytes(2, "little")
    blocks = [user_data[i:i + 16] for i in range(0, len(user_data), 16)]
    for i, b in enumerate(blocks):
        c = crc(b)
        if corrupt and i == len(blocks) - 1:
            c ^= 0x5A5A
        out += b + c.to_bytes(2, "little")
    return out


def response(seq, body=b"", transport=0xC0, tseq=0):
    """Transport header + RESPONSE (FIR, FIN, the request's SEQ) + IIN 00 00."""
    return bytes([transport | (tseq & 0x3F), 0xC0 | (seq & 0x0F), 0x81, 0x00, 0x00]) + body


# Class 0 of the hostile outstation when it behaves: analog input 0 = 5
# (g30v1, start-stop 0..0).
GOOD_CLASS0 = bytes([30, 1, 0, 0, 0, 0x01]) + (5).to_bytes(4, "little", signed=True)
# The object header claims analog inputs 0..9 (ten g30v1, 50 octets) and
# two follow.
SHORT_CLASS0 = bytes([30, 1, 0, 0, 9]) + (bytes([0x01]) + (77).to_bytes(4, "little")) * 2


class Hostile:
    def __init__(self, port):
        self.port = port
        self.mode = "crc"
        self.requests = []  # (mode, function)
        self.sent = {}      # mode -> answers sent
        self.octets = {}    # mode -> octets sent
        self.conns = []
        self.accepts = 0
        self.sock = socket.socket()
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind(("127.0.0.1", port))
        # Port 0: the kernel's choice, bound at once (no race for it).
        self.port = self.sock.getsockname()[1]
        self.sock.listen(4)
        self.sock.settimeout(0.5)
        self.running = True
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        while self.running:
            try:
                c, _ = self.sock.accept()
            except OSError:
                continue
            self.accepts += 1
            self.conns.append(c)
            threading.Thread(target=self._serve, args=(c,), daemon=True).start()

    def drop_connections(self):
        for c in self.conns:
            try:
                c.shutdown(socket.SHUT_RDWR)
                c.close()
            except OSError:
                pass
        self.conns = []

    def _serve(self, c):
        c.settimeout(0.5)
        buf = b""
        while self.running:
            try:
                got = c.recv(4096)
            except socket.timeout:
                continue
            except OSError:
                return
            if not got:
                return
            buf += got
            while len(buf) >= 10 and buf[:2] == b"\x05\x64":
                n = buf[2] - 5
                total = 10 + n + 2 * ((n + 15) // 16)
                if len(buf) < total:
                    break
                frame, buf = buf[:total], buf[total:]
                data = b"".join(frame[10 + 18 * i: 10 + 18 * i + min(16, n - 16 * i)] for i in range((n + 15) // 16))
                if len(data) < 3:
                    continue
                seq, function = data[1] & 0x0F, data[2]
                # A READ of class 0 (g60v1) is an integrity poll.
                class0 = function == 1 and b"\x3c\x01" in data[3:]
                mode = self.mode
                self.requests.append((mode, function))
                if function == 0:  # CONFIRM
                    continue
                try:
                    out = self.answer(mode, seq, function, class0)
                    c.sendall(out)
                    self.sent[mode] = self.sent.get(mode, 0) + 1
                    self.octets[mode] = self.octets.get(mode, 0) + len(out)
                except OSError:
                    return
            if buf and buf[:2] != b"\x05\x64":
                buf = b""

    def answer(self, mode, seq, function, class0):
        body = GOOD_CLASS0 if class0 else b""
        if mode == "crc":
            return link_frame(response(seq, body), corrupt=True)
        if mode == "fir_no_fin":
            # The first of two transport segments; the second never comes.
            return link_frame(response(seq, body, transport=0x40))
        if mode == "short_objects":
            return link_frame(response(seq, SHORT_CLASS0 if class0 else b""))
        if mode == "garbage":
            rnd = random.Random(len(self.requests))
            junk = bytes(rnd.choice([b for b in range(256) if b != 0x05]) for _ in range(64))
            return junk
        return link_frame(response(seq, body))

    def close(self):
        self.running = False
        self.drop_connections()
        self.sock.close()


# ---------------------------------------------------------------------------
# gridscada's API.

def metric(text, name, label):
    """The value of `name` whose device (or link) label is `label`."""
    for l in text.splitlines():
        if l.startswith(name + "{") and (f'device="{label}"' in l or f'link="{label}"' in l):
            return float(l.split()[-1])
    return None


TAGS = """
[[device]]
name = "OS1"
description = "dnp3py 0.6.0 outstation"
protocol = "dnp3"
address = "127.0.0.1:{p1}"

[device.dnp3]
event_poll_period_s = 1
unsolicited = false
response_timeout_ms = 2000

[[device]]
name = "OS2"
description = "py1815 0.3.0 outstation"
protocol = "dnp3"
address = "127.0.0.1:{p2}"

[device.dnp3]
event_poll_period_s = 0
unsolicited = true
response_timeout_ms = 2000

[[device]]
name = "OS3"
description = "dnp3py 0.6.0 outstation on a serial line"
protocol = "dnp3"

[device.serial]
port = "{serial}"
baud = 19200

[device.dnp3]
event_poll_period_s = 1
unsolicited = false
response_timeout_ms = 2000

[[tag]]
name = "OS3.Power"
device = "OS3"
units = "kW"
dnp3 = {{ point = "analog_input", index = 0 }}

[[tag]]
name = "OS3.Q1.Closed"
device = "OS3"
type = "bool"
writable = true
write_role = "operator"
dnp3 = {{ point = "binary_input", index = 2, command = "crob", command_index = 0, select = true }}

[[device]]
name = "HB"
description = "A hostile outstation"
protocol = "dnp3"
address = "127.0.0.1:{ph}"

[device.dnp3]
event_poll_period_s = 1
unsolicited = false
response_timeout_ms = 1500

[[tag]]
name = "OS1.Alarm"
device = "OS1"
type = "bool"
dnp3 = {{ point = "binary_input", index = 0 }}

[[tag]]
name = "OS1.Remote"
device = "OS1"
type = "bool"
dnp3 = {{ point = "binary_input", index = 1 }}

[[tag]]
name = "OS1.Power"
device = "OS1"
units = "kW"
dnp3 = {{ point = "analog_input", index = 0 }}

[[tag]]
name = "OS1.Energy"
device = "OS1"
units = "kWh"
dnp3 = {{ point = "counter", index = 0 }}

[[tag]]
name = "OS1.Q1.Closed"
device = "OS1"
description = "Feeder breaker Q1 closed"
type = "bool"
writable = true
write_role = "operator"
states = {{ false = "OPEN", true = "CLOSED" }}
dnp3 = {{ point = "binary_input", index = 2, command = "crob", command_index = 0, select = true }}

[[tag]]
name = "OS1.Pump"
device = "OS1"
type = "bool"
writable = true
write_role = "operator"
dnp3 = {{ point = "binary_output", index = 1, command = "crob" }}

[[tag]]
name = "OS1.Setpoint"
device = "OS1"
units = "kW"
writable = true
write_role = "operator"
min = 0.0
max = 500.0
dnp3 = {{ point = "analog_input", index = 1, command = "analog_output", command_index = 0 }}

[[tag]]
name = "OS2.Breaker"
device = "OS2"
type = "bool"
dnp3 = {{ point = "double_bit", index = 0 }}

[[tag]]
name = "OS2.Trip"
device = "OS2"
type = "bool"
dnp3 = {{ point = "binary_input", index = 1 }}

[[tag]]
name = "OS2.Volts"
device = "OS2"
units = "V"
dnp3 = {{ point = "analog_input", index = 0 }}

[[tag]]
name = "OS2.Count"
device = "OS2"
dnp3 = {{ point = "counter", index = 0 }}

[[tag]]
name = "OS2.Q0"
device = "OS2"
type = "bool"
writable = true
write_role = "operator"
dnp3 = {{ point = "binary_input", index = 2, command = "crob", command_index = 0, select = true }}

[[tag]]
name = "OS2.Q1"
device = "OS2"
type = "bool"
writable = true
write_role = "operator"
dnp3 = {{ point = "binary_output", index = 1, command = "crob", select = true }}

[[tag]]
name = "OS2.Limit"
device = "OS2"
type = "i32"
writable = true
write_role = "operator"
min = 0
max = 100
dnp3 = {{ point = "analog_input", index = 1, command = "analog_output", command_index = 0, select = true }}

[[tag]]
name = "HB.A0"
device = "HB"
dnp3 = {{ point = "analog_input", index = 0 }}
"""

MAIN = """
tag_files = ["dnp3.toml"]

[server]
http = "127.0.0.1:8080"
data_dir = "data"

[storage]
url = "sqlite://gridscada.db"
"""


def good(api, name, value=None):
    t = api.tag(name)
    if not t or (t.get("quality") or {}).get("code") != "good":
        return None
    if value is not None and t.get("value") != value:
        return None
    return t


def quality(api, name):
    t = api.tag(name) or {}
    return f"{t.get('value')!r} {json.dumps(t.get('quality'))}"


def main():
    tmp = tempfile.mkdtemp(prefix="gridscada-dnp3-")
    # The hostile outstation listens from the start, on a port of its own.
    hostile = Hostile(0)
    hostile.mode = "good"
    ph = hostile.port
    p1, p2, p3, http_port = free_port(), free_port(), free_port(), free_port()
    serial = os.path.join(tmp, "ttyDNP3")
    plant = os.path.join(tmp, "plant")
    os.makedirs(plant)
    with open(os.path.join(plant, "gridscada.toml"), "w") as f:
        f.write(MAIN)
    with open(os.path.join(plant, "dnp3.toml"), "w") as f:
        f.write(TAGS.format(p1=p1, p2=p2, ph=ph, serial=serial))

    r = subprocess.run([BIN, "check", plant], capture_output=True, text=True, timeout=60)
    check(r.returncode == 0, "gridscada check takes the DNP3 plant", r.stdout + r.stderr)

    # The wire check: every frame of the session, dissected by Wireshark's
    # DNP3 dissector afterwards.
    cap = os.path.join(tmp, "dnp3.pcapng")
    tshark = subprocess.Popen(
        ["tshark", "-q", "-i", "lo", "-f", f"tcp port {p1} or tcp port {p2} or tcp port {p3} or tcp port {ph}",
         "-w", cap],
        stdout=subprocess.DEVNULL, stderr=open(os.path.join(tmp, "tshark.log"), "w"),
        preexec_fn=die_with_parent)
    wait_for(lambda: os.path.exists(cap), 10)
    time.sleep(1)
    peers = []
    proc = None
    line = None
    log_path = os.path.join(tmp, "server.log")
    try:
        os1 = Peer("dnp3py", DNP3PY, p1, tmp)
        peers.append(os1)
        os2 = Peer("py1815", PY1815, p2, tmp)
        peers.append(os2)
        os3 = Peer("dnp3py-serial", DNP3PY, p3, tmp)
        peers.append(os3)
        line = SerialLine(serial, p3, tmp)
        data = os.path.join(tmp, "data")
        log = open(log_path, "w")
        # The outstations are the Python peers, not the demo's simulated ones.
        proc = subprocess.Popen([BIN, "demo", "--config", plant, "--http", f"127.0.0.1:{http_port}",
                                 "--data", data, "--real-device", "OS1", "--real-device", "OS2",
                                 "--real-device", "OS3", "--real-device", "HB"], stdout=log, stderr=subprocess.STDOUT,
                                preexec_fn=die_with_parent)
        run(f"http://127.0.0.1:{http_port}", data, proc, os1, os2, os3, line, hostile, log_path)
    except Exception as e:  # a broken harness is a failure, not a traceback
        import traceback
        check(False, "the test ran to its end", f"{e!r}\n{traceback.format_exc()}")
    finally:
        if proc is not None:
            check(proc.poll() is None, "gridscada is still running at the end",
                  f"exit code {proc.poll()}")
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)
        if line is not None:
            line.stop()
        for p in peers:
            p.stop()
        hostile.close()
        time.sleep(1)
        tshark.terminate()
        try:
            tshark.wait(10)
        except subprocess.TimeoutExpired:
            tshark.kill()
        wire_check(cap, [p1, p2, p3], ph)
        if checks.FAILED:
            for p in peers:
                print(f"--- {p.name} said (last 15 lines) ---")
                print("\n".join(p.lines[-15:]))
                print(p.stderr_tail())
            print("--- server log (last 60 lines) ---")
            try:
                print("".join(open(log_path).readlines()[-60:]))
            except OSError:
                pass
            print(f"(everything is in {tmp})")
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    print(f"{checks.PASSED} passed, {checks.FAILED} failed ({time.time() - STARTED:.0f} s)")
    sys.exit(1 if checks.FAILED else 0)


def run(base, data, proc, os1, os2, os3, line, hostile, log_path):
    api, user = login(base, data, proc)
    check(api is not None, "gridscada demo --config serves the DNP3 plant and logs in")
    if api is None:
        return

    # -- The integrity poll brings every point, Good.
    expected = {
        "OS1.Alarm": False, "OS1.Remote": True, "OS1.Power": 42.0, "OS1.Energy": 7,
        "OS1.Q1.Closed": False, "OS1.Pump": False, "OS1.Setpoint": 10.0,
        "OS2.Breaker": True, "OS2.Trip": False, "OS2.Volts": 1234.0, "OS2.Count": 555,
        "OS2.Q0": False, "OS2.Q1": False, "OS2.Limit": 20,
        "HB.A0": 5.0,
    }
    for name, want in expected.items():
        t = wait_for(lambda: good(api, name), 20)
        got = t.get("value") if t else None
        same = got is not None and (abs(got - want) < 1e-6 if isinstance(want, float) else got == want)
        check(same, f"integrity poll: {name} = {want!r}, Good", f"got {quality(api, name)}")
    src = (api.tag("OS1.Q1.Closed") or {}).get("source") or {}
    note(f"OS1.Q1.Closed's source in the API: {json.dumps(src)}")

    # -- Events with the outstation's time, to the millisecond.
    # dnp3py: a counter event (g22v5, with time), found by the event poll.
    stamp = int(time.time() * 1000) - 1234
    os1.send(f"COUNTER 8 {stamp}")
    t = wait_for(lambda: good(api, "OS1.Energy", 8), 10)
    check(t is not None and t.get("timestamp") == stamp,
          "dnp3py: a counter event (g22v5, event poll) carries the outstation's time as the timestamp, to the ms",
          f"got {t}, want timestamp {stamp}")
    # dnp3py: an analog event without time (g32v1) takes the receive time.
    before = int(time.time() * 1000)
    os1.send("ANALOG 43")
    t = wait_for(lambda: good(api, "OS1.Power", 43.0), 10)
    check(t is not None and before - 50 <= t.get("timestamp", 0) <= int(time.time() * 1000) + 50,
          "dnp3py: an analog event without time (g32v1) arrives, stamped when it was received", f"got {t}")
    # py1815: an unsolicited binary event (no event polls), with its time.
    stamp = int(time.time() * 1000) - 250
    os2.send(f"EVENT {stamp} 1")
    t = wait_for(lambda: good(api, "OS2.Trip", True), 10)
    check(t is not None and t.get("timestamp") == stamp,
          "py1815: an unsolicited binary event carries the outstation's time as the timestamp, to the ms",
          f"got {t}, want timestamp {stamp}")
    stamp = int(time.time() * 1000) - 777
    os2.send(f"ANALOG 1240 {stamp}")
    t = wait_for(lambda: good(api, "OS2.Volts", 1240.0), 10)
    check(t is not None and t.get("timestamp") == stamp,
          "py1815: an unsolicited analog event (g32v3) carries the outstation's time, to the ms",
          f"got {t}, want timestamp {stamp}")
    check(wait_for(lambda: os2.said("TIME"), 5),
          "py1815: the outstation asked for the time (IIN1.4) and was given it (LAN procedure)", str(os2.lines[-5:]))
    status, body = api.call("GET", "/api/events?limit=200")
    synced = [e for e in (body or {}).get("events", [])
              if e.get("source") == "OS2" and e.get("kind") == "device" and "NEED_TIME" in e.get("message", "")]
    check(synced, "the clock set at the outstation's request is in the event log", json.dumps(synced)[:300])

    # -- Commands through the audited write.
    status, body = api.call("POST", "/api/tags/OS1.Q1.Closed/write", {"value": True})
    check(status == 200, "dnp3py: closing breaker Q1 (CROB, select before operate) is confirmed (200)",
          f"{status} {body}")
    note(f"the write's answer shows OS1.Q1.Closed = {body.get('value')!r} at {body.get('timestamp')}")
    t0 = time.time()
    back = wait_for(lambda: good(api, "OS1.Q1.Closed", True), 3)
    note(f"OS1.Q1.Closed reads True after {time.time() - t0:.1f} s: {back is not None} ({quality(api, 'OS1.Q1.Closed')})")
    check(good(api, "OS1.Alarm", False) is not None, "dnp3py: binary input 0 is untouched by the command to output 0",
          quality(api, "OS1.Alarm"))
    # The outstation's lines are read by a thread: they may follow the answer.
    wait_for(lambda: os1.said("OPERATE 0"), 3)
    cmds = [l for l in os1.lines if l.split()[0] in ("SELECT", "OPERATE", "DIRECT")]
    check(cmds == ["SELECT 0 3", "OPERATE 0 3"], "dnp3py: the outstation saw SELECT, then OPERATE (LATCH_ON)",
          str(cmds))
    # A whole number: dnp3py returns it on a 32-bit integer analog input.
    status, body = api.call("POST", "/api/tags/OS1.Setpoint/write", {"value": 125})
    note(f"the write's answer shows OS1.Setpoint = {body.get('value')!r}")
    check(status == 200 and wait_for(lambda: os1.said("DIRECT_AO 0 125"), 5),
          "dnp3py: a set point (g41, direct operate) is confirmed and reached the outstation",
          f"{status} {body} {os1.said('DIRECT_AO')}")
    status, body = api.call("POST", "/api/tags/OS1.Pump/write", {"value": True})
    msg = json.dumps(body)
    wait_for(lambda: os1.said("DIRECT 1"), 3)
    check(status == 502 and "HARDWARE_ERROR" in msg and os1.said("DIRECT 1 3") and not os1.said("SELECT 1"),
          "dnp3py: a direct operate the outstation refuses fails, naming HARDWARE_ERROR", f"{status} {msg}")
    n = len(os1.lines)
    status, body = api.call("POST", "/api/tags/OS1.Setpoint/write", {"value": 900})
    time.sleep(0.3)
    check(status == 400 and len(os1.lines) == n,
          "a set point outside the engineering limits is refused before anything is sent",
          f"{status} {body} {os1.lines[n:]}")
    status, body = api.call("POST", "/api/tags/OS2.Q0/write", {"value": True})
    wait_for(lambda: os2.said("OPERATE g12:0"), 3)
    check(status == 200 and os2.said("SELECT g12:0") and os2.said("OPERATE g12:0"),
          "py1815: output 0 (CROB, select before operate) is confirmed, selected then operated",
          f"{status} {body} {os2.lines[-6:]}")
    status, body = api.call("POST", "/api/tags/OS2.Limit/write", {"value": 60})
    wait_for(lambda: os2.said("OPERATE g41:0"), 3)
    check(status == 200 and os2.said("SELECT g41:0") and os2.said("OPERATE g41:0"),
          "py1815: an analog output (g41, select before operate) is confirmed", f"{status} {body} {os2.lines[-6:]}")
    n = len(os2.lines)
    status, body = api.call("POST", "/api/tags/OS2.Limit/write", {"value": 101})
    time.sleep(0.3)
    check(status == 400 and len(os2.lines) == n,
          "py1815: an analog output above its max is refused before anything is sent", f"{status} {body}")
    status, body = api.call("POST", "/api/tags/OS2.Q1/write", {"value": True})
    msg = json.dumps(body)
    wait_for(lambda: os2.said("SELECT g12:1"), 3)
    check(status == 502 and "NOT_AUTHORIZED" in msg, "py1815: a control the outstation refuses fails, naming NOT_AUTHORIZED",
          f"{status} {msg}")
    check(not os2.said("OPERATE g12:1"), "py1815: the refused select is not followed by an OPERATE",
          str(os2.lines[-6:]))

    status, body = api.call("GET", "/api/events?limit=100")
    events = (body or {}).get("events", [])
    text = json.dumps(events)
    writes = [e for e in events if "OS1.Q1.Closed" in json.dumps(e)]
    check(status == 200 and writes and user in json.dumps(writes),
          f"the event log records the breaker's write with the user ({user})", text[:400])
    check("OS2.Q1" in text and "NOT_AUTHORIZED" in text, "the event log records the refused control with its status",
          text[:400])
    note("event log, OS1.Q1.Closed: " + json.dumps(writes[:2])[:400])

    # -- The devices API and /metrics: per device.
    dev1, link1 = api.device("OS1")
    dev2, _ = api.device("OS2")
    check(dev1 and dev1.get("protocol") == "dnp3" and dev1.get("connected") and dev1.get("requests", 0) > 0
          and (dev1.get("telecontrol") or {}).get("events", 0) > 0 and (dev1.get("telecontrol") or {}).get("commands", 0) >= 3
          and (dev1.get("telecontrol") or {}).get("commands_failed", 0) >= 1,
          "devices API: OS1 is a connected dnp3 device with requests, events, commands and a failed one counted",
          json.dumps(dev1))
    check(dev2 and dev2.get("connected") and (dev2.get("telecontrol") or {}).get("commands_failed", 0) >= 1,
          "devices API: OS2 counts its refused command", json.dumps(dev2))
    m = api.metrics()
    want = [(n, d) for d in ("OS1", "OS2", "HB") for n in (
        "gridscada_dnp3_requests_total", "gridscada_dnp3_events_total", "gridscada_dnp3_commands_total",
        "gridscada_dnp3_commands_failed_total", "gridscada_dnp3_overflows_total", "gridscada_dnp3_timeouts_total")]
    missing = [f"{n}{{device={d}}}" for n, d in want if metric(m, n, d) is None]
    check(not missing, "/metrics: every gridscada_dnp3_* counter, per device", f"missing {missing}")
    check((metric(m, "gridscada_dnp3_commands_total", "OS1") or 0) >= 2
          and (metric(m, "gridscada_dnp3_commands_failed_total", "OS2") or 0) >= 1
          and (metric(m, "gridscada_dnp3_events_total", "OS1") or 0) >= 2,
          "/metrics: OS1's commands and events, OS2's failed command",
          "\n".join(l for l in m.splitlines() if l.startswith("gridscada_dnp3")))

    # -- The outstation restarts (IIN1.7): the connection drops, the values
    # turn bad, the new process says DEVICE_RESTART, the master clears it and
    # polls: the values are back, Good.
    _, link1 = api.device("OS1")
    connects_before = (link1 or {}).get("connects", 0)
    n_log = len(open(log_path).readlines())
    os1.stop()
    bad = wait_for(lambda: (api.tag("OS1.Power") or {}).get("quality", {}).get("code") == "bad", 10)
    check(bad, "dnp3py stopped: its values turn Bad", quality(api, "OS1.Power"))
    # Down past the comm alarm's on-delay (2 s).
    alarm = wait_for(lambda: "OS1:comm" in (api.active_alarms() or []), 6)
    check(alarm, "dnp3py stopped: the device's comm alarm (OS1:comm) activates", str(api.active_alarms()))
    os1.lines.clear()
    os1.start()
    t = wait_for(lambda: good(api, "OS1.Power", 42.0), 20)
    check(t is not None and good(api, "OS1.Remote", True) is not None and good(api, "OS1.Energy", 7) is not None,
          "dnp3py restarted: its values come back Good (the restarted outstation's)",
          f"{quality(api, 'OS1.Power')} {quality(api, 'OS1.Energy')}")
    log_lines = open(log_path).readlines()[n_log:]
    restart = [l for l in log_lines if "IIN1.7" in l or "restarted" in l]
    check(restart, "the restart (IIN1.7 DEVICE_RESTART) is in the server's log", "".join(log_lines[-10:]))
    _, link1 = api.device("OS1")
    check((link1 or {}).get("connects", 0) == connects_before + 1,
          "devices API: OS1's link counts the reconnection", json.dumps(link1))
    status, body = api.call("GET", "/api/events?limit=200")
    kinds = sorted({(e.get("source"), e.get("kind")) for e in (body or {}).get("events", [])})
    note(f"event log after the restart (source, kind): {kinds}")
    restarted = [e for e in (body or {}).get("events", [])
                 if e.get("source") == "OS1" and e.get("kind") == "device" and "IIN1.7" in e.get("message", "")]
    check(restarted, "the restart (IIN1.7) is in the event log, from the outstation", str(kinds))
    cleared = wait_for(lambda: "OS1:comm" not in (api.active_alarms() or ["?"]), 10)
    check(cleared, "dnp3py restarted: OS1:comm clears", str(api.active_alarms()))
    note(f"OS1.Comm.LastError after the restart: {(api.tag('OS1.Comm.LastError') or {}).get('value')!r}")
    note("restart in the server log: "
         + (re.sub(r"\x1b\[[0-9;]*m", "", restart[0]).strip()[:300] if restart else "nothing"))

    serial_cases(api, os3, line)

    # -- Hostile outstations.
    hostile_cases(api, hostile)


class SerialLine:
    """A pseudo-terminal at `path` joined by socat to an outstation's TCP
    port: to gridscada, a serial port with an outstation on it."""

    def __init__(self, path, port, tmp):
        self.path, self.port, self.tmp = path, port, tmp
        self.proc = None
        self.start()

    def start(self):
        self.proc = subprocess.Popen(
            ["socat", f"pty,link={self.path},raw,echo=0", f"tcp:127.0.0.1:{self.port}"],
            stdout=subprocess.DEVNULL, stderr=open(os.path.join(self.tmp, "socat.log"), "a"),
            preexec_fn=die_with_parent)
        if not wait_for(lambda: os.path.exists(self.path) or self.proc.poll() is not None, 10) \
                or not os.path.exists(self.path):
            raise RuntimeError(f"socat did not make {self.path}")

    def stop(self):
        if self.proc and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)


def serial_cases(api, os3, line):
    """OS3 is on a serial line: the integrity poll brings its values, a
    breaker is closed with select-before-operate over the line, the line is
    pulled (the port disappears: values Bad, comm alarm) and put back (the
    port is opened again, values Good)."""
    t = wait_for(lambda: good(api, "OS3.Power", 42.0), 20)
    check(t is not None and good(api, "OS3.Q1.Closed", False) is not None,
          "serial line: the integrity poll brings OS3's values, Good",
          f"{quality(api, 'OS3.Power')} {quality(api, 'OS3.Q1.Closed')}")
    dev, _ = api.device("OS3")
    note(f"devices API, OS3: {json.dumps(dev)[:300]}")
    check(dev and dev.get("protocol") == "dnp3" and dev.get("address") == line.path and dev.get("connected"),
          "devices API: OS3 is a connected dnp3 device at its serial port", json.dumps(dev)[:400])
    status, body = api.call("POST", "/api/tags/OS3.Q1.Closed/write", {"value": True})
    wait_for(lambda: os3.said("OPERATE 0"), 3)
    cmds = [l for l in os3.lines if l.split()[0] in ("SELECT", "OPERATE", "DIRECT")]
    check(status == 200 and cmds == ["SELECT 0 3", "OPERATE 0 3"],
          "serial line: closing OS3's breaker (CROB, select before operate) is confirmed; the outstation saw SELECT, OPERATE",
          f"{status} {body} {cmds}")
    line.stop()
    bad = wait_for(lambda: (api.tag("OS3.Power") or {}).get("quality", {}).get("code") == "bad", 15)
    check(bad, "serial line pulled (the port is gone): OS3's values turn Bad", quality(api, "OS3.Power"))
    alarm = wait_for(lambda: "OS3:comm" in (api.active_alarms() or []), 10)
    check(alarm, "serial line pulled: OS3's comm alarm activates", str(api.active_alarms()))
    note(f"OS3.Comm.LastError with the line pulled: {(api.tag('OS3.Comm.LastError') or {}).get('value')!r}")
    status, body = api.call("POST", "/api/tags/OS3.Q1.Closed/write", {"value": False})
    check(status == 502 and "nothing was sent" in json.dumps(body),
          "serial line pulled: a command fails at once, saying nothing was sent", f"{status} {body}")
    line.start()
    t = wait_for(lambda: good(api, "OS3.Power", 42.0), 30)
    check(t is not None, "serial line back: the port is opened again and OS3's values are Good",
          quality(api, "OS3.Power"))
    cleared = wait_for(lambda: "OS3:comm" not in (api.active_alarms() or ["?"]), 15)
    check(cleared, "serial line back: OS3:comm clears", str(api.active_alarms()))


def hostile_cases(api, hostile):
    """Each hostile answer in turn, on a new connection:

    - bad CRC: each frame dropped and its octets counted (garbage_bytes),
      the last error names the CRC; three in a row close the connection
      (reconnected with back-off); the device shows not connected, its comm
      alarm active, its tags Bad;
    - FIR without FIN: the segment waits for the rest until the response
      timeout (counted, tags Bad); nothing counted as malformed;
    - object header longer than the fragment: the fragment is malformed as
      a whole, counted and named; none of its values is used;
    - garbage: as a bad CRC.

    Then the outstation answers correctly on the same connection: the
    integrity poll that failed is asked again and the tags come back."""
    def garbage():
        _, link = api.device("HB")
        return (link or {}).get("garbage_bytes", 0)

    def metric_garbage():
        link = (api.device("HB")[1] or {}).get("link", "?")
        return metric(api.metrics(), "gridscada_link_garbage_bytes_total", link) or 0

    def last_error():
        return str((api.tag("HB.Comm.LastError") or {}).get("value"))

    cases = [
        ("crc", "link frames whose user data CRC is wrong", "CRC"),
        ("fir_no_fin", "a transport segment with FIR and no FIN, never continued", "no response"),
        ("short_objects", "an object header claiming ten analog inputs, two present", "objects"),
        ("garbage", "garbage octets", "garbage"),
    ]
    for mode, what, word in cases:
        g0, t0 = garbage(), (api.device("HB")[0] or {}).get("timeouts", 0)
        accepts0 = hostile.accepts
        # The mode changes, then the connection drops: gridscada connects
        # again, runs its startup (unsolicited responses are off: the
        # integrity poll first) and gets the hostile answers.
        hostile.mode = mode
        hostile.drop_connections()
        started = time.time()
        wait_for(lambda: hostile.sent.get(mode), 10)
        # A timeout of an earlier case may have left "no response" as the
        # last error: a new one is counted first.
        timeouts = lambda: (api.device("HB")[0] or {}).get("timeouts", 0)
        t_sent = timeouts()
        err = wait_for(lambda: word.lower() in last_error().lower()
                       and (mode != "fir_no_fin" or timeouts() > t_sent), 10)
        check(bool(err), f"hostile ({what}): HB's last error names it ('{word}')",
              f"{last_error()} / answers sent {hostile.sent.get(mode)}")
        # Let it run for a while: the other devices go on meanwhile. The
        # device's connected flag, sampled.
        seen, tag_seen, errors_seen = [], [], {last_error()}
        end = time.time() + 3
        while time.time() < end:
            seen.append(bool((api.device("HB")[0] or {}).get("connected")))
            errors_seen.add(last_error())
            tag_seen.append((api.tag("HB.Comm.Connected") or {}).get("value"))
            time.sleep(0.2)
        check(api.healthz() == 200, f"hostile ({what}): gridscada goes on, /healthz answers 200")
        check(good(api, "OS2.Volts") is not None and good(api, "OS1.Remote") is not None,
              f"hostile ({what}): OS1 and OS2 stay Good meanwhile",
              f"{quality(api, 'OS2.Volts')} {quality(api, 'OS1.Remote')}")
        dev, link = api.device("HB")
        q = (api.tag("HB.A0") or {})
        g1, t1 = garbage(), (dev or {}).get("timeouts", 0)
        note(f"{mode}: after {time.time() - started:.1f} s: HB.A0 {q.get('value')!r} "
             f"{json.dumps(q.get('quality'))}; connected={(dev or {}).get('connected')}; "
             f"last_error={last_error()!r}; garbage_bytes {g0}->{g1}; timeouts {t0}->{t1}; "
             f"reconnects={hostile.accepts - accepts0}; answers sent={hostile.sent.get(mode)} "
             f"({hostile.octets.get(mode)} octets); "
             f"metrics garbage={metric_garbage()}; connected sampled: {seen.count(True)} true, "
             f"{seen.count(False)} false; HB.Comm.Connected sampled: {tag_seen.count(True)} true, "
             f"{tag_seen.count(False)} false; active alarms: {api.active_alarms()}")
        if mode in ("crc", "garbage", "short_objects"):
            check(g1 > g0, f"hostile ({what}): counted in the devices API's garbage_bytes ({g0} -> {g1})")
        if mode in ("crc", "garbage"):
            def closed():
                errors_seen.add(last_error())
                return hostile.accepts - accepts0 >= 2 and any(
                    "3 malformed frames in a row" in e for e in errors_seen)
            wait_for(closed, 10)
            check(closed(),
                  f"hostile ({what}): three malformed frames in a row close the connection, reconnected",
                  f"{sorted(errors_seen)}; connections {hostile.accepts - accepts0}")
            check(seen.count(True) == 0 and "HB:comm" in api.active_alarms(),
                  f"hostile ({what}): HB shows not connected, its comm alarm active",
                  f"connected sampled {seen}; alarms {api.active_alarms()}")
        if mode == "short_objects":
            check(q.get("value") != 77 or q.get("quality", {}).get("code") != "good",
                  f"hostile ({what}): none of the malformed fragment's values is used",
                  f"HB.A0 {q.get('value')!r} {json.dumps(q.get('quality'))}")
        if mode in ("crc", "fir_no_fin", "garbage"):
            check(t1 > t0 and q.get("quality", {}).get("code") == "bad",
                  f"hostile ({what}): the poll times out (counted) and HB.A0 turns Bad",
                  f"timeouts {t0}->{t1}, {json.dumps(q.get('quality'))}")
    # The devices API's and /metrics' garbage counters agree.
    note("/metrics, links: " + " | ".join(l for l in api.metrics().splitlines() if l.startswith("gridscada_link_garbage")))
    check(metric_garbage() == garbage() > 0, "/metrics: HB's gridscada_link_garbage_bytes_total = the devices API's",
          f"{metric_garbage()} vs {garbage()}")

    # Recovery. The outstation answers correctly again on the same
    # connection: the integrity poll that failed is asked again (5 s after
    # its failure) and HB.A0 comes back.
    hostile.mode = "good"
    n = len(hostile.requests)
    t = wait_for(lambda: good(api, "HB.A0", 5.0), 10)
    check(t is not None, "hostile outstation correct again on the same connection: the failed integrity poll is asked again, HB.A0 Good",
          f"{quality(api, 'HB.A0')}; requests since: {[f for _, f in hostile.requests[n:]]}")
    # After a reconnect the startup's integrity poll brings it back.
    hostile.drop_connections()
    t = wait_for(lambda: good(api, "HB.A0", 5.0), 10)
    check(t is not None, "hostile outstation correct again, after a reconnect: HB.A0 is Good again",
          quality(api, "HB.A0"))
    check(api.healthz() == 200 and good(api, "OS2.Volts") is not None and good(api, "OS1.Remote") is not None,
          "after the hostile cases: /healthz 200, OS1 and OS2 Good")


def wire_check(cap, ports, hostile_port):
    decode = [a for p in ports + [hostile_port] if p != 20000 for a in ("-d", f"tcp.port=={p},dnp3")]
    count = subprocess.run(["tshark", "-r", cap, *decode, "-Y", "dnp3"], capture_output=True, text=True, timeout=60)
    packets = len(count.stdout.splitlines())
    # Everything on the good outstations' ports, both ways, and everything
    # gridscada sent to the hostile one (its answers are meant to be bad).
    scope = " || ".join([f"tcp.port == {p}" for p in ports] + [f"tcp.dstport == {hostile_port}"])
    bad = subprocess.run(["tshark", "-r", cap, *decode, "-Y",
                          f"({scope}) && (_ws.malformed || _ws.expert.severity >= error)"],
                         capture_output=True, text=True, timeout=60)
    lines = bad.stdout.splitlines()
    check(packets > 50 and not lines and bad.returncode == 0,
          f"tshark dissects the session's {packets} DNP3 packets with no malformed or expert-error packet",
          "\n".join(lines[:10]) + bad.stderr[-300:] + count.stderr[-300:])
    per_port = {}
    for p in ports:
        r = subprocess.run(["tshark", "-r", cap, *decode, "-Y", f"dnp3 && tcp.port == {p}"],
                           capture_output=True, text=True, timeout=60)
        per_port[p] = len(r.stdout.splitlines())
    check(all(n > 10 for n in per_port.values()), "tshark: every outstation's session is in the capture (OS3's on the TCP side of its serial line)",
          str(per_port))
    # On dnp3py's port: each of its two starts answered with IIN1.7 and was
    # followed by gridscada's WRITE g80v1 (index 7 cleared); the breaker's
    # SELECT then OPERATE of a CROB (g12v1), then the pump's DIRECT_OPERATE.
    def fields(port, flt, *names):
        r = subprocess.run(["tshark", "-r", cap, *decode, "-Y", f"dnp3 && {flt}", "-T", "fields",
                            *[a for n in names for a in ("-e", n)]], capture_output=True, text=True, timeout=60)
        return [l.split("\t") for l in r.stdout.splitlines()]
    p1 = ports[0]
    restarts = fields(p1, f"tcp.srcport == {p1} && dnp3.al.iin.rst == 1", "frame.number")
    clears = fields(p1, f"tcp.dstport == {p1} && dnp3.al.func == 2 && dnp3.al.obj == 0x5001", "frame.number")
    check(len(restarts) >= 2 and len(clears) == 2,
          "tshark: dnp3py's two starts set IIN1.7, each cleared by a WRITE of g80v1",
          f"responses with IIN1.7: {len(restarts)}, WRITE g80v1: {len(clears)}")
    crob = [f for f, o in fields(p1, f"tcp.dstport == {p1} && dnp3.al.func", "dnp3.al.func", "dnp3.al.obj")
            if o == "0x0c01"]
    check(crob == ["3", "4", "5"],
          "tshark: the CROBs (g12v1) went out as SELECT, OPERATE (the breaker), DIRECT_OPERATE (the pump)", str(crob))
    # What tshark thinks of the hostile answers (for the record).
    hb = subprocess.run(["tshark", "-r", cap, *decode, "-Y",
                         f"tcp.srcport == {hostile_port} && (_ws.malformed || _ws.expert.severity >= warning)"],
                        capture_output=True, text=True, timeout=60)
    note(f"tshark on the hostile answers: {len(hb.stdout.splitlines())} flagged packets")


class Interrupted(Exception):
    pass


def interrupted(signum, frame):
    raise Interrupted(f"signal {signum}")


if __name__ == "__main__":
    # Stopped from outside (a CI timeout): cleaned up, counted as a failure.
    signal.signal(signal.SIGTERM, interrupted)
    main()
