#!/usr/bin/env python3
"""Interoperability: gridscada's poller against pymodbus servers.

Starts two pymodbus servers holding known values of every data type the
configuration offers (bool on coils and discrete inputs, bit in a register,
i16, u16, i32, u32, i64, u64, f32, f64, string; every word and byte order;
scale and offset):

- Modbus TCP on a free loopback port, with two unit ids behind it (a gateway);
- Modbus RTU on one end of a pseudo-terminal pair made by socat, the poller
  on the other end.

Then writes a gridscada configuration for them, runs the `interop_poll`
example (the real field I/O, polling once and printing every tag as JSON),
checks every decoded value against the value encoded here with pymodbus's own
converters, and checks that the writes the poller made (coil, register,
multi-register f32 and i32, bit in a register) landed in pymodbus's tables.

Last, a slow device (every reply 0.2 s late, nine blocks, so a scan takes
about 2 s): writes land in the middle of its scans, and each confirmed value
must never be replaced by the scan's older reading (`--watch-ms`).

Usage: interop_pymodbus_server.py INTEROP_POLL_BINARY
Prints one line per check and a closing "N passed, M failed"; exits 1 on
any failure.
"""

import asyncio
import json
import math
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time

try:
    from pymodbus.client.mixin import ModbusClientMixin
    from pymodbus.datastore import (
        ModbusSequentialDataBlock,
        ModbusServerContext,
        ModbusSlaveContext,
    )
    from pymodbus.framer import FramerType
    from pymodbus.server import ModbusSerialServer, ModbusTcpServer
except ImportError as e:  # the README test command installs it
    print(f"FAIL: pymodbus is not importable ({e}); pip install -r tests/requirements.txt")
    print("0 passed, 1 failed")
    sys.exit(1)

DT = ModbusClientMixin.DATATYPE
CONVERT = ModbusClientMixin.convert_to_registers

PASSED = 0
FAILED = 0


def check(ok, what, detail=""):
    global PASSED, FAILED
    if ok:
        PASSED += 1
        print(f"PASS {what}")
    else:
        FAILED += 1
        print(f"FAIL {what}: {detail}")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def swap_bytes(regs):
    return [((r & 0xFF) << 8) | (r >> 8) for r in regs]


def f32_round(x):
    """The f64 a device's f32 reads as."""
    return struct.unpack(">f", struct.pack(">f", x))[0]


# Register types: (data type, pymodbus converter type, value, expected engineering value).
REGISTER_VALUES = [
    ("i16", DT.INT16, -12345, -12345),
    ("u16", DT.UINT16, 54321, 54321),
    ("i32", DT.INT32, -123456789, -123456789),
    ("u32", DT.UINT32, 3000000000, 3000000000),
    ("i64", DT.INT64, -1234567890123456789, -1234567890123456789),
    ("u64", DT.UINT64, 1234567890123456789, 1234567890123456789),
    ("f32", DT.FLOAT32, -1234.5, -1234.5),
    ("f32", DT.FLOAT32, 0.1, f32_round(0.1)),
    ("f64", DT.FLOAT64, math.pi, math.pi),
    ("f64", DT.FLOAT64, -6.02214076e23, -6.02214076e23),
]
ORDERS = [("big", "big"), ("little", "big"), ("big", "little"), ("little", "little")]


class DevicePlan:
    """The tags of one simulated device and the tables that hold them."""

    def __init__(self, name, unit, salt):
        self.name = name
        self.unit = unit
        self.ir = {}  # address -> register
        self.hr = {}
        self.co = {}
        self.di = {}
        self.tags = []  # (toml text, tag name, expected value, exact?)
        self.writes = []  # (tag, value text, check function on the context)
        self._build(salt)

    def tag(self, suffix, kind, address, expected, exact=True, **extra):
        name = f"{self.name}.{suffix}"
        lines = [
            "[[tag]]",
            f'name = "{name}"',
            f'device = "{self.name}"',
            f'kind = "{kind}"',
            f"address = {address}",
        ]
        for k, v in extra.items():
            key = "type" if k == "type_" else k
            if isinstance(v, bool):
                lines.append(f"{key} = {'true' if v else 'false'}")
            elif isinstance(v, str):
                lines.append(f'{key} = "{v}"')
            else:
                lines.append(f"{key} = {v}")
        self.tags.append(("\n".join(lines) + "\n", name, expected, exact))
        return name

    def _build(self, salt):
        # salt makes the units behind one gateway hold different values, so a
        # reply from the wrong unit cannot pass.
        # Coils and discrete inputs.
        for a, v in [(0, True), (1, False), (2, True), (17, salt % 2 == 0)]:
            self.co[a] = v
            self.tag(f"Coil{a}", "coil", a, v)
            self.di[a + 3] = not v
            self.tag(f"DI{a + 3}", "discrete_input", a + 3, not v)
        # Bit in a register: input register 0 = 0xA005 (bits 0, 2, 13, 15).
        self.ir[0] = 0xA005
        for bit in (0, 1, 2, 13, 15):
            self.tag(f"IR0.Bit{bit}", "input_register", 0, bool(0xA005 >> bit & 1), bit=bit)
        # ...with little byte order: 0x0100 on the wire is 0x0001.
        self.ir[1] = 0x0100
        for bit in (0, 8):
            self.tag(
                f"IR1.Bit{bit}.LE",
                "input_register",
                1,
                bit == 0,
                bit=bit,
                byte_order="little",
            )
        # Every register type in every word and byte order, on input registers.
        addr = 10
        for i, (ty, dt, raw, expected) in enumerate(REGISTER_VALUES):
            if isinstance(raw, int) and ty.startswith("i"):
                raw = raw + salt if raw < 0 else raw - salt
                expected = raw
            elif isinstance(raw, int):
                raw = raw - salt
                expected = raw
            for wo, bo in ORDERS:
                regs = CONVERT(raw, dt, word_order=wo)
                if bo == "little":
                    regs = swap_bytes(regs)
                for k, r in enumerate(regs):
                    self.ir[addr + k] = r
                self.tag(
                    f"{ty.upper()}_{i}.W{wo[0].upper()}B{bo[0].upper()}",
                    "input_register",
                    addr,
                    expected,
                    type_=ty,
                    word_order=wo,
                    byte_order=bo,
                )
                addr += len(regs)
        # u64 above i64::MAX: exact, not rounded through a float.
        big = 18446744073709551000 - salt
        regs = CONVERT(big, DT.UINT64)
        for k, r in enumerate(regs):
            self.ir[addr + k] = r
        self.tag("U64_Big", "input_register", addr, big, type_="u64")
        addr += 4
        # Strings: even length, odd length (NUL padded), little byte order.
        for label, text, length, bo in [
            ("Str", f"GRIDSCADA-{salt:02d}", 8, "big"),
            ("StrOdd", "ABC", 2, "big"),
            ("StrLE", "Feeder 7", 4, "little"),
        ]:
            regs = CONVERT(text, DT.STRING)
            regs += [0] * (length - len(regs))
            if bo == "little":
                regs = swap_bytes(regs)
            for k, r in enumerate(regs):
                self.ir[addr + k] = r
            self.tag(label, "input_register", addr, text, type_="string", length=length, byte_order=bo)
            addr += length
        # Scale and offset: raw 2315 * 0.1 = 231.5 V; raw -50 * 0.5 + 10 = -15.
        self.ir[addr] = 2315
        self.tag("V_Scaled", "input_register", addr, 231.5, exact=False, scale=0.1, units="V")
        self.ir[addr + 1] = CONVERT(-50, DT.INT16)[0]
        self.tag("I16_Scaled", "input_register", addr + 1, -15.0, type_="i16", scale=0.5, offset=10.0)
        # A register far away: its own block.
        self.ir[4000] = 4000 + salt
        self.tag("IR4000", "input_register", 4000, 4000 + salt)

        # Holding registers and a coil that the poller writes.
        w = dict(writable=True, write_role="operator")
        self.hr[0] = 1000 + salt
        self.tag("SP_U16", "holding_register", 0, 1000 + salt, **w)
        self.writes.append(("SP_U16", "4321", ("hr", 0, [4321])))
        sp = f32_round(12.5 + salt)
        for k, r in enumerate(CONVERT(sp, DT.FLOAT32)):
            self.hr[2 + k] = r
        self.tag("SP_F32", "holding_register", 2, sp, type_="f32", **w)
        self.writes.append(("SP_F32", "47.25", ("hr", 2, CONVERT(47.25, DT.FLOAT32))))
        for k, r in enumerate(CONVERT(-1.5, DT.FLOAT32, word_order="little")):
            self.hr[4 + k] = r
        self.tag("SP_F32_WL", "holding_register", 4, -1.5, type_="f32", word_order="little", **w)
        self.writes.append(
            ("SP_F32_WL", "-0.5", ("hr", 4, CONVERT(-0.5, DT.FLOAT32, word_order="little")))
        )
        le = swap_bytes(CONVERT(7, DT.INT32, word_order="little"))
        for k, r in enumerate(le):
            self.hr[6 + k] = r
        self.tag("SP_I32_LL", "holding_register", 6, 7, type_="i32", word_order="little", byte_order="little", **w)
        self.writes.append(
            ("SP_I32_LL", "-7", ("hr", 6, swap_bytes(CONVERT(-7, DT.INT32, word_order="little"))))
        )
        # Bit 3 of a register whose other bits must survive the write.
        self.hr[10] = 0x8001
        self.tag("HR10.Bit3", "holding_register", 10, False, bit=3, **w)
        self.writes.append(("HR10.Bit3", "true", ("hr", 10, [0x8009])))
        self.co[10] = False
        self.tag("Cmd", "coil", 10, False, **w)
        self.writes.append(("Cmd", "true", ("co", 10, [True])))

    def context(self):
        def block(values, size, fill):
            data = [fill] * size
            for a, v in values.items():
                data[a] = v
            # ModbusSlaveContext adds 1 to every protocol address.
            return ModbusSequentialDataBlock(1, data)

        return ModbusSlaveContext(
            di=block(self.di, 64, False),
            co=block(self.co, 64, False),
            hr=block(self.hr, 64, 0),
            ir=block(self.ir, 4100, 0),
        )

    def device_toml(self, transport):
        return f'[[device]]\nname = "{self.name}"\n{transport}unit_id = {self.unit}\nscan_ms = 200\ntimeout_ms = 1000\nretries = 2\n\n'


def same(expected, got, exact):
    if isinstance(expected, bool) or isinstance(expected, str):
        return type(got) is type(expected) and got == expected
    if got is None or isinstance(got, (bool, str)):
        return False
    if exact:
        return got == expected and (isinstance(expected, float) or isinstance(got, int))
    return math.isclose(got, expected, rel_tol=1e-12, abs_tol=1e-9)


class Servers:
    """pymodbus servers on their own asyncio loop in a daemon thread."""

    def __init__(self):
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.servers = []

    def run(self, coro, timeout=10):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def start(self, make):
        async def go():
            server = make()
            self.servers.append(server)
            asyncio.get_running_loop().create_task(server.serve_forever())

        self.run(go())

    def stop(self):
        async def go():
            for s in self.servers:
                try:
                    await s.shutdown()
                except Exception:  # noqa: BLE001 - best effort at exit
                    pass

        try:
            self.run(go(), timeout=5)
        except Exception:  # noqa: BLE001
            pass


class SlowBlock(ModbusSequentialDataBlock):
    """Holding registers that answer every access 0.2 s late."""

    def getValues(self, address, count=1):  # noqa: N802 - pymodbus's name
        time.sleep(0.2)
        return super().getValues(address, count)


SLOW_BLOCKS = 9


def slow_device_interleaving(poll_bin, work):
    """Writes to a slow device interleave with its scans and never roll back."""
    servers = Servers()  # its own loop: the sleeps must not stall the others
    try:
        ctx = ModbusServerContext(
            slaves={
                1: ModbusSlaveContext(
                    hr=SlowBlock(1, [0] * (SLOW_BLOCKS * 40 + 8)),
                    ir=ModbusSequentialDataBlock(1, [0] * 8),
                    co=ModbusSequentialDataBlock(1, [False] * 8),
                    di=ModbusSequentialDataBlock(1, [False] * 8),
                )
            },
            single=False,
        )
        port = free_port()
        servers.start(lambda: ModbusTcpServer(ctx, address=("127.0.0.1", port)))
        check(wait_for(lambda: port_open(port), 10), f"slow pymodbus server listens on 127.0.0.1:{port}")
        # Blocks 40 registers apart (past max_gap): one request each.
        text = (
            f'[[device]]\nname = "SLOW"\nprotocol = "tcp"\naddress = "127.0.0.1:{port}"\n'
            "unit_id = 1\nscan_ms = 200\ntimeout_ms = 1500\nretries = 0\n\n"
        )
        for b in range(SLOW_BLOCKS):
            extra = 'writable = true\nwrite_role = "operator"\n' if b == 0 else ""
            text += (
                f'[[tag]]\nname = "SLOW.R{b}"\ndevice = "SLOW"\nkind = "holding_register"\n'
                f"address = {b * 40}\n{extra}\n"
            )
        folder = os.path.join(work, "slow")
        os.makedirs(folder)
        with open(os.path.join(folder, "tags.toml"), "w") as f:
            f.write(text)
        with open(os.path.join(folder, "gridscada.toml"), "w") as f:
            f.write('tag_files = ["tags.toml"]\n')
        values = [4101, 4102, 4103]
        cmd = [poll_bin, "--config", folder, "--wait-s", "20", "--watch-ms", "2500"]
        for v in values:
            cmd += ["--write", f"SLOW.R0={v}"]
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        writes = []
        for line in run.stdout.splitlines():
            try:
                obj = json.loads(line)
            except json.JSONDecodeError:
                continue
            if "write" in obj:
                writes.append(obj)
        check(len(writes) == len(values), "slow device: every write answered", run.stderr[-500:])
        for v, w in zip(values, writes):
            check(w.get("ok") is True and w.get("value") == v,
                  f"slow device: write SLOW.R0 := {v} confirmed mid-scan", str(w))
            check(w.get("rollbacks") == 0,
                  f"slow device: SLOW.R0 = {v} never replaced by an older scan's reading", str(w))
        check(ctx[1].getValues(3, 0, 1) == [values[-1]], "slow device holds the last value written")
    finally:
        servers.stop()


def wait_for(pred, seconds):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.05)
    return pred()


def port_open(port):
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        return False


def main():
    if len(sys.argv) != 2:
        print(__doc__)
        sys.exit(2)
    poll_bin = sys.argv[1]
    # So `finally` below stops socat when the wrapper is killed.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))
    work = tempfile.mkdtemp(prefix="gridscada-interop-")
    socat = None
    servers = Servers()
    try:
        # --- the devices -----------------------------------------------------
        gw1 = DevicePlan("T1", 1, 0)
        gw2 = DevicePlan("T2", 2, 3)
        rtu = DevicePlan("R5", 5, 5)
        port = free_port()
        tcp_ctx = ModbusServerContext(slaves={1: gw1.context(), 2: gw2.context()}, single=False)
        servers.start(lambda: ModbusTcpServer(tcp_ctx, address=("127.0.0.1", port)))
        check(wait_for(lambda: port_open(port), 10), f"pymodbus TCP server listens on 127.0.0.1:{port}")

        devices = [
            (gw1, f'protocol = "tcp"\naddress = "127.0.0.1:{port}"\n', tcp_ctx[1]),
            (gw2, f'protocol = "tcp"\naddress = "127.0.0.1:{port}"\n', tcp_ctx[2]),
        ]
        server_end = os.path.join(work, "pty-server")
        poller_end = os.path.join(work, "pty-poller")
        if shutil.which("socat") is None:
            check(False, "socat for the RTU pseudo-terminal pair", "socat not found (apt-get install socat)")
        else:
            socat = subprocess.Popen(
                [
                    "socat",
                    "-d",
                    "-d",
                    f"pty,raw,echo=0,link={server_end}",
                    f"pty,raw,echo=0,link={poller_end}",
                ],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            ok = wait_for(lambda: os.path.exists(server_end) and os.path.exists(poller_end), 10)
            check(ok, "socat pseudo-terminal pair")
            if ok:
                rtu_ctx = ModbusServerContext(slaves={5: rtu.context()}, single=False)
                servers.start(
                    lambda: ModbusSerialServer(
                        rtu_ctx,
                        framer=FramerType.RTU,
                        port=server_end,
                        baudrate=19200,
                        bytesize=8,
                        parity="N",
                        stopbits=1,
                    )
                )
                devices.append(
                    (
                        rtu,
                        f'protocol = "rtu"\n[device.serial]\nport = "{poller_end}"\nbaud = 19200\n',
                        rtu_ctx[5],
                    )
                )

        # --- the gridscada configuration -------------------------------------
        # [device.serial] must close the device table, so tags follow devices.
        text = ""
        for d, transport, _ in devices:
            if "[device.serial]" in transport:
                head, serial = transport.split("[device.serial]\n", 1)
                text += d.device_toml(head).rstrip("\n") + "\n[device.serial]\n" + serial + "\n"
            else:
                text += d.device_toml(transport)
        for d, _, _ in devices:
            text += "\n".join(t[0] for t in d.tags) + "\n"
        with open(os.path.join(work, "tags.toml"), "w") as f:
            f.write(text)
        main_file = os.path.join(work, "gridscada.toml")
        with open(main_file, "w") as f:
            f.write('tag_files = ["tags.toml"]\n')

        # --- poll once, with writes ------------------------------------------
        cmd = [poll_bin, "--config", main_file, "--wait-s", "20"]
        for d, _, _ in devices:
            for tag, value, _ in d.writes:
                cmd += ["--write", f"{d.name}.{tag}={value}"]
        started = time.monotonic()
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        print(f"interop_poll exited {run.returncode} after {time.monotonic() - started:.1f} s")
        if run.stderr.strip():
            print("interop_poll stderr (last lines):")
            for line in run.stderr.strip().splitlines()[-15:]:
                print("  " + line)
        tags, writes = {}, {}
        for line in run.stdout.splitlines():
            try:
                obj = json.loads(line)
            except json.JSONDecodeError:
                check(False, "interop_poll output is JSON lines", repr(line))
                continue
            if "tag" in obj:
                tags[obj["tag"]] = obj
            elif "write" in obj:
                writes[obj["write"]] = obj
        check(run.returncode == 0, "interop_poll read every tag Good and confirmed every write",
              f"exit status {run.returncode}")

        # --- every decoded value ---------------------------------------------
        # Writable tags were read before the writes; their values here are the
        # written ones (checked below), so only read-only tags are compared.
        for d, _, ctx in devices:
            written = {f"{d.name}.{t}" for t, _, _ in d.writes}
            for _, name, expected, exact in d.tags:
                if name in written:
                    continue
                got = tags.get(name)
                if got is None:
                    check(False, f"read {name}", "missing from the output")
                    continue
                ok = got.get("quality") == "good" and same(expected, got.get("value"), exact)
                check(ok, f"read {name} = {expected!r}",
                      f"got {got.get('value')!r} quality {got.get('quality')} ({got.get('reason')})")
            check(tags.get(f"{d.name}.Comm.Connected", {}).get("value") is True,
                  f"{d.name}.Comm.Connected is true", str(tags.get(f"{d.name}.Comm.Connected")))

            # --- the writes, as pymodbus saw them ----------------------------
            for tag, value, (table, addr, want) in d.writes:
                name = f"{d.name}.{tag}"
                w = writes.get(name)
                check(w is not None and w.get("ok") is True, f"write {name} := {value} confirmed",
                      str(w))
                fc = {"hr": 3, "co": 1}[table]
                have = ctx.getValues(fc, addr, len(want))
                have = [bool(x) for x in have] if table == "co" else list(have)
                check(have == want, f"pymodbus holds {name} = {value} ({table} {addr})",
                      f"server has {have}, expected {want}")
                back = tags.get(name, {})
                if value in ("true", "false"):
                    expect_back = value == "true"
                else:
                    expect_back = float(value) if "." in value else int(value)
                check(back.get("quality") == "good" and back.get("value") == expect_back,
                      f"read-back of {name} = {value}", str(back))

        slow_device_interleaving(poll_bin, work)
    finally:
        servers.stop()
        if socat is not None:
            socat.terminate()
            try:
                socat.wait(5)
            except subprocess.TimeoutExpired:
                socat.kill()
        shutil.rmtree(work, ignore_errors=True)

    print(f"{PASSED} passed, {FAILED} failed")
    sys.exit(1 if FAILED else 0)


if __name__ == "__main__":
    main()
