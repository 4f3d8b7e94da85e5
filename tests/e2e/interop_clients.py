#!/usr/bin/env python3
"""Interoperability: third-party Modbus clients against gridscada's simulators.

Runs `gridscada sim --config DIR` on a copy of the demo plant (tags/*.toml)
whose device ports are moved to free loopback ports (so it runs next to a
running demo), then:

(a) pymodbus's client reads the documented registers of every demo device
    (docs/REGISTER_MAPS.md) and checks plausible values: ELCB closed, analyzer
    V ~ 231, PF, Hz, the load meter's Q at PF 0.95, the wind speed, ...; writes
    a zone command coil and sees the zone status input follow; writes a
    setpoint (function 16) and starts the diesel; checks the documented
    exceptions (unit not behind the gateway, past the table's end, NaN setpoint).
(b) mbpoll (libmodbus) reads discrete inputs, coils, input registers (floats,
    u32) and holding registers, with zero-based and one-based references, and
    writes a coil and a holding register.

Usage: interop_clients.py GRIDSCADA_BINARY REPO_ROOT
Prints one line per check and a closing "N passed, M failed"; exits 1 on
any failure.
"""

import glob
import math
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time

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
    return ok


def finish():
    print(f"{PASSED} passed, {FAILED} failed")
    sys.exit(1 if FAILED else 0)


def free_ports(n):
    socks = []
    try:
        for _ in range(n):
            s = socket.socket()
            s.bind(("127.0.0.1", 0))
            socks.append(s)
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def port_open(port):
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        return False


def wait_for(pred, seconds, step=0.05):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(step)
    return pred()


def f32(regs):
    return struct.unpack(">f", struct.pack(">HH", *regs))[0]


def u32(regs):
    return (regs[0] << 16) | regs[1]


# ---------------------------------------------------------------------------
# (a) pymodbus client


def pymodbus_checks(ports):
    from pymodbus.client import ModbusTcpClient
    from pymodbus.client.mixin import ModbusClientMixin

    def client(port):
        c = ModbusTcpClient("127.0.0.1", port=port, timeout=2, retries=1)
        check(c.connect(), f"pymodbus connects to 127.0.0.1:{port}")
        return c

    def good(r):
        return r is not None and not r.isError()

    for panel in ("SS1", "CSS1"):
        c = client(ports[panel])
        try:
            r = c.read_discrete_inputs(0, count=4, slave=1)
            if check(good(r), f"{panel} unit 1 (I-7044) discrete inputs 0-3", str(r)):
                elcb, mccb, door, spare = r.bits[:4]
                check(elcb is True, f"{panel}.ELCB.Closed is true", str(r.bits[:4]))
                check(mccb is True, f"{panel}.MCCB.Closed is true", str(r.bits[:4]))
                check(door is False and spare is False, f"{panel} door closed, spare input 0", str(r.bits[:4]))
            r = c.read_coils(0, count=8, slave=1)
            if check(good(r), f"{panel} unit 1 coils 0-7", str(r)):
                check(r.bits[0] is False, f"{panel}.ELCB.Reset is off", str(r.bits[:8]))
                check(r.bits[1] is True, f"{panel}.MCCB.Cmd is on (close)", str(r.bits[:8]))
            r = c.read_discrete_inputs(0, count=16, slave=2)
            if check(good(r), f"{panel} unit 2 (I-7051) discrete inputs 0-15", str(r)):
                bits = r.bits[:16]
                check(bits[0:4] == [True] * 4, f"{panel} zones 1-4 closed", str(bits))
                check(bits[8:12] == [True] * 4, f"{panel} zones 1-4 energised", str(bits))
                check(bits[4:8] == [False] * 4 and bits[12:16] == [False] * 4, f"{panel} spare inputs 0", str(bits))
            r = c.read_coils(0, count=13, slave=3)
            if check(good(r), f"{panel} unit 3 (I-7042) coils 0-12", str(r)):
                check(r.bits[0:4] == [True] * 4, f"{panel} zone commands 1-4 on", str(r.bits[:13]))
            p_before = None
            r = c.read_input_registers(0, count=22, slave=4)
            if check(good(r), f"{panel} unit 4 (analyzer) input registers 0-21", str(r)):
                regs = r.registers
                v = [f32(regs[i : i + 2]) for i in (0, 2, 4)]
                i_ = [f32(regs[i : i + 2]) for i in (6, 8, 10)]
                p, q, pf, hz = (f32(regs[i : i + 2]) for i in (12, 14, 16, 18))
                kwh = u32(regs[20:22])
                p_before = p
                check(all(225 < x < 235 for x in v), f"{panel}.PA.V_L1..3 ~ 231 V", str(v))
                check(all(0 < x < 100 for x in i_), f"{panel}.PA.I_L1..3 plausible", str(i_))
                # Four zones of 2.5 + 4 + 3 + 5.5 kW, each swinging 5 %.
                check(13.0 < p < 17.0, f"{panel}.PA.P_kW ~ 15 kW", str(p))
                check(0 < q < p, f"{panel}.PA.Q_kvar plausible", str(q))
                check(0.85 < pf < 0.97, f"{panel}.PA.PF between the zones' 0.88 and 0.95", str(pf))
                s = math.hypot(p, q)
                check(abs(pf - p / s) < 0.01, f"{panel}.PA.PF = P/S", f"PF {pf}, P/S {p / s}")
                check(49.9 < hz < 50.1, f"{panel}.PA.Hz ~ 50", str(hz))
                check(0 <= kwh < 10_000_000, f"{panel}.PA.kWh counter readable", str(kwh))
                # Sum of phase currents × V ≈ S (within the model's rounding).
                s_va = sum(a * b for a, b in zip(v, i_)) / 1000
                check(abs(s_va - s) / s < 0.05, f"{panel} analyzer ΣV·I ≈ S", f"ΣVI {s_va:.2f} kVA, S {s:.2f} kVA")

            # Open zone 2 (coil 1 of unit 3): its status and voltage follow.
            r = c.write_coil(1, False, slave=3)
            check(good(r), f"{panel} write zone 2 command coil off (function 05)", str(r))
            opened = wait_for(
                lambda: (lambda x: good(x) and x.bits[1] is False and x.bits[9] is False)(
                    c.read_discrete_inputs(0, count=16, slave=2)
                ),
                3,
            )
            check(opened, f"{panel}.Zone2.Closed and .Energised follow the open command")
            if p_before is not None:
                r = c.read_input_registers(12, count=2, slave=4)
                if good(r):
                    p_after = f32(r.registers)
                    check(p_before - p_after > 2.5, f"{panel}.PA.P_kW drops with zone 2 (4 kW) open",
                          f"{p_before:.2f} -> {p_after:.2f}")
            r = c.write_coils(0, [True, True, True, True], slave=3)
            check(good(r), f"{panel} write zone commands 1-4 on (function 15)", str(r))
            closed = wait_for(
                lambda: (lambda x: good(x) and x.bits[0:4] == [True] * 4)(c.read_discrete_inputs(0, count=4, slave=2)),
                3,
            )
            check(closed, f"{panel} zone 2 closes again")

            # Documented exceptions.
            r = c.read_coils(0, count=1, slave=9)
            check(r is not None and r.isError() and getattr(r, "exception_code", None) == 0x0B,
                  f"{panel} unit 9 (not behind the gateway) answers exception 0x0B", str(r))
            r = c.read_input_registers(20, count=10, slave=4)
            check(r is not None and r.isError() and getattr(r, "exception_code", None) == 0x02,
                  f"{panel} analyzer read past register 21 answers exception 0x02", str(r))
        finally:
            c.close()

    # Microgrid units.
    def regs_f32(c, fn, addr, n, what):
        r = fn(addr, count=2 * n, slave=1)
        if not check(good(r), what, str(r)):
            return None
        return [f32(r.registers[i : i + 2]) for i in range(0, 2 * n, 2)]

    c = client(ports["MG.PV1"])
    try:
        vals = regs_f32(c, c.read_input_registers, 0, 5, "MG.PV1 input registers 0-9 (f32)")
        r = c.read_input_registers(10, count=1, slave=1)
        if check(good(r), "MG.PV1.State readable", str(r)):
            check(r.registers[0] in (0, 1, 2, 3), "MG.PV1.State is 0-3", str(r.registers))
        if vals:
            p, v, i_, avail, g = vals
            check(0 <= g <= 1000.5, "MG.PV1.Irradiance within 0-1000 W/m²", str(g))
            check(abs(avail - 100 * g / 1000 * 0.95) < 0.05, "MG.PV1.Available_kW = rated × G/1000 × 0.95",
                  f"available {avail}, G {g}")
            check(-0.01 <= p <= avail + 0.5, "MG.PV1.P_kW within 0..available", f"P {p}, available {avail}")
            check(195.5 <= v <= 264.5, "MG.PV1.V within ±15 % of 230 V", str(v))
            check(abs(i_ - abs(p) * 1000 / (3 * v)) < 0.05, "MG.PV1.I = |P|·1000/(3·V)", f"I {i_}, P {p}, V {v}")
        sp = regs_f32(c, c.read_holding_registers, 0, 1, "MG.PV1 holding register 0 (setpoint)")
        if sp:
            check(abs(sp[0] - 100.0) < 1e-3 or sp[0] == 40.0, "MG.PV1.Setpoint_kW starts at rated 100 kW", str(sp))
        regs = ModbusClientMixin.convert_to_registers(40.0, ModbusClientMixin.DATATYPE.FLOAT32)
        r = c.write_registers(0, regs, slave=1)
        check(good(r), "MG.PV1 write setpoint 40 kW (function 16)", str(r))
        sp = regs_f32(c, c.read_holding_registers, 0, 1, "MG.PV1 setpoint read back")
        if sp:
            check(sp[0] == 40.0, "MG.PV1.Setpoint_kW reads back 40", str(sp))
        ok = wait_for(lambda: (lambda x: x is not None and x[0] <= 40.5)(
            regs_f32(c, c.read_input_registers, 0, 1, "MG.PV1.P_kW")), 10, step=0.5)
        check(ok, "MG.PV1.P_kW follows the 40 kW setpoint (at most 40)")
        nan = ModbusClientMixin.convert_to_registers(float("nan"), ModbusClientMixin.DATATYPE.FLOAT32)
        r = c.write_registers(0, nan, slave=1)
        check(r is not None and r.isError() and getattr(r, "exception_code", None) == 0x03,
              "MG.PV1 NaN setpoint answers exception 0x03", str(r))
        sp = regs_f32(c, c.read_holding_registers, 0, 1, "MG.PV1 setpoint after the NaN write")
        if sp:
            check(sp[0] == 40.0, "MG.PV1 NaN setpoint not taken", str(sp))
    finally:
        c.close()

    c = client(ports["MG.WT1"])
    try:
        vals = regs_f32(c, c.read_input_registers, 0, 5, "MG.WT1 input registers 0-9 (f32)")
        if vals:
            p, v, i_, avail, wind = vals
            check(abs(wind - 8.0) < 1e-6, "MG.WT1.WindSpeed is the default 8 m/s", str(wind))
            check(0 < avail < 50, "MG.WT1.Available_kW on the power curve (0 < P < rated at 8 m/s)", str(avail))
            check(-0.01 <= p <= avail + 0.5, "MG.WT1.P_kW within 0..available", f"P {p}, available {avail}")
    finally:
        c.close()

    c = client(ports["MG.BESS1"])
    try:
        vals = regs_f32(c, c.read_input_registers, 0, 5, "MG.BESS1 input registers 0-9 (f32)")
        if vals:
            p, v, i_, soc_kwh, soc_pct = vals
            check(20 <= soc_kwh <= 190, "MG.BESS1.SoC_kWh within [soc_min, soc_max]", str(soc_kwh))
            check(abs(soc_pct - soc_kwh / 200 * 100) < 0.1, "MG.BESS1.SoC_pct = SoC_kWh / 200 kWh",
                  f"{soc_pct} % vs {soc_kwh} kWh")
            check(-50.01 <= p <= 60.01, "MG.BESS1.P_kW within charge/discharge limits", str(p))
    finally:
        c.close()

    c = client(ports["MG.DG1"])
    try:
        r = c.read_coils(0, count=1, slave=1)
        if check(good(r), "MG.DG1.RunCmd coil readable", str(r)):
            check(r.bits[0] is False, "MG.DG1.RunCmd starts off", str(r.bits[:1]))
        r = c.read_discrete_inputs(0, count=1, slave=1)
        if check(good(r), "MG.DG1.Running input readable", str(r)):
            check(r.bits[0] is False, "MG.DG1.Running starts false", str(r.bits[:1]))
        r = c.write_coil(0, True, slave=1)
        check(good(r), "MG.DG1 write RunCmd on (function 05)", str(r))
        ok = wait_for(lambda: (lambda x: good(x) and x.registers[0] == 3)(c.read_input_registers(10, count=1, slave=1)), 3)
        check(ok, "MG.DG1.State goes to 3 (starting) after RunCmd")
        r = c.write_coil(0, False, slave=1)
        check(good(r), "MG.DG1 write RunCmd off", str(r))
    finally:
        c.close()

    c = client(ports["MG.Load"])
    try:
        vals = regs_f32(c, c.read_input_registers, 0, 4, "MG.Load input registers 0-7 (f32)")
        if vals:
            p, q, v, hz = vals
            check(55 <= p <= 110, "MG.Load.P_kW within the demand profile (60 kW + peaks)", str(p))
            tan = math.tan(math.acos(0.95))
            check(abs(q - p * tan) < 0.02 * p + 0.01, "MG.Load.Q_kvar at PF 0.95", f"P {p}, Q {q}")
            check(195.5 <= v <= 264.5, "MG.Load.V within ±15 % of 230 V", str(v))
            check(47.5 <= hz <= 52.5, "MG.Load.Hz within 47.5-52.5", str(hz))
    finally:
        c.close()


# ---------------------------------------------------------------------------
# (b) mbpoll


def mbpoll(args, write=None):
    cmd = ["mbpoll", "-m", "tcp", "-o", "2", "-1"] + args + ["127.0.0.1"]
    if write is not None:
        cmd += (["--"] if any(str(w).startswith("-") for w in write) else []) + [str(w) for w in write]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
    values = {}
    for m in re.finditer(r"^\[(\d+)\]:\s+(\S+)", p.stdout, re.M):
        values[int(m.group(1))] = m.group(2)
    return p, values


def mbpoll_checks(ports):
    ss1 = str(ports["SS1"])
    css1 = str(ports["CSS1"])
    pv = str(ports["MG.PV1"])

    p, v = mbpoll(["-p", ss1, "-a", "1", "-t", "1", "-r", "0", "-c", "4", "-0"])
    check(p.returncode == 0 and [v.get(i) for i in range(4)] == ["1", "1", "0", "0"],
          "mbpoll SS1 unit 1 discrete inputs 0-3 (-0): ELCB, MCCB closed, door closed", f"{v} {p.stderr.strip()}")
    # Without -0 references are one-based: reference 1 is address 0 (the ELCB).
    p, v = mbpoll(["-p", ss1, "-a", "1", "-t", "1", "-r", "1", "-c", "2"])
    check(p.returncode == 0 and v.get(1) == "1" and v.get(2) == "1",
          "mbpoll one-based references: -r 1 reads address 0", f"{v} {p.stderr.strip()}")
    p, v = mbpoll(["-p", css1, "-a", "2", "-t", "1", "-r", "0", "-c", "16", "-0"])
    check(p.returncode == 0 and [v.get(i) for i in (0, 1, 2, 3, 8, 9, 10, 11)] == ["1"] * 8,
          "mbpoll CSS1 unit 2 zone status and voltage inputs all 1", f"{v} {p.stderr.strip()}")
    p, v = mbpoll(["-p", css1, "-a", "3", "-t", "0", "-r", "0", "-c", "13", "-0"])
    check(p.returncode == 0 and [v.get(i) for i in range(4)] == ["1"] * 4,
          "mbpoll CSS1 unit 3 coils: zone commands on", f"{v} {p.stderr.strip()}")
    p, v = mbpoll(["-p", css1, "-a", "4", "-t", "3:float", "-B", "-r", "0", "-c", "10", "-0"])
    try:
        fl = {k: float(x) for k, x in v.items()}
    except ValueError:
        fl = {}
    check(p.returncode == 0 and all(225 < fl.get(k, 0) < 235 for k in (0, 2, 4)),
          "mbpoll CSS1 analyzer V_L1..3 as big-endian floats ~ 231 V", f"{v} {p.stderr.strip()}")
    check(49.9 < fl.get(18, 0) < 50.1, "mbpoll CSS1 analyzer Hz ~ 50", str(v))
    p, v = mbpoll(["-p", css1, "-a", "4", "-t", "3:int", "-B", "-r", "20", "-c", "1", "-0"])
    check(p.returncode == 0 and v.get(20, "x").isdigit(), "mbpoll CSS1 analyzer kWh (u32) readable", f"{v} {p.stderr.strip()}")

    # Write a coil: open zone 3 of CSS1 and see its status input follow.
    p, _ = mbpoll(["-p", css1, "-a", "3", "-t", "0", "-r", "2", "-0"], write=[0])
    check(p.returncode == 0 and "Written 1 references" in p.stdout, "mbpoll writes CSS1 zone 3 command coil 0",
          p.stdout[-200:] + p.stderr)

    def zone3():
        _, v = mbpoll(["-p", css1, "-a", "2", "-t", "1", "-r", "2", "-c", "1", "-0"])
        return v.get(2)

    check(wait_for(lambda: zone3() == "0", 5, step=0.1), "mbpoll sees CSS1 zone 3 status open")
    p, _ = mbpoll(["-p", css1, "-a", "3", "-t", "0", "-r", "2", "-0"], write=[1])
    check(p.returncode == 0 and wait_for(lambda: zone3() == "1", 5, step=0.1), "mbpoll closes CSS1 zone 3 again",
          p.stderr)

    # Holding registers: write the PV setpoint as a float (function 16), read
    # it as raw registers, then change the high word alone (function 06).
    p, _ = mbpoll(["-p", pv, "-a", "1", "-t", "4:float", "-B", "-r", "0", "-0"], write=[25.5])
    check(p.returncode == 0, "mbpoll writes MG.PV1 setpoint 25.5 as a float", p.stdout[-200:] + p.stderr)
    p, v = mbpoll(["-p", pv, "-a", "1", "-t", "4:hex", "-r", "0", "-c", "2", "-0"])
    want = ["0x%04X" % x for x in struct.unpack(">HH", struct.pack(">f", 25.5))]
    check(p.returncode == 0 and [v.get(0, "").upper().replace("0X", "0x"), v.get(1, "").upper().replace("0X", "0x")] == want,
          "mbpoll reads MG.PV1 setpoint registers 0x41CC 0x0000", f"{v} {p.stderr.strip()}")
    p, _ = mbpoll(["-p", pv, "-a", "1", "-t", "4", "-r", "0", "-0"], write=[0x4248])
    check(p.returncode == 0, "mbpoll writes MG.PV1 holding register 0 = 0x4248 (function 06)", p.stdout[-200:] + p.stderr)
    p, v = mbpoll(["-p", pv, "-a", "1", "-t", "4:float", "-B", "-r", "0", "-c", "1", "-0"])
    check(p.returncode == 0 and v.get(0) == "50", "mbpoll reads MG.PV1 setpoint 50 (0x4248 0x0000)", f"{v} {p.stderr.strip()}")

    # Errors reach a third-party client as Modbus exceptions.
    p, _ = mbpoll(["-p", ss1, "-a", "4", "-t", "3", "-r", "22", "-c", "1", "-0"])
    check(p.returncode != 0 and "Illegal data address" in (p.stdout + p.stderr),
          "mbpoll read past the analyzer's table: illegal data address", (p.stdout + p.stderr)[-300:])


def main():
    if len(sys.argv) != 3:
        print(__doc__)
        sys.exit(2)
    binary, root = sys.argv[1], sys.argv[2]
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))

    help_text = subprocess.run([binary, "--help"], capture_output=True, text=True).stdout
    if not re.search(r"^\s+sim\b", help_text, re.M):
        check(False, "gridscada has a `sim` command",
              f"`{binary} --help` lists no `sim` subcommand; these tests run `gridscada sim --config DIR`")
        finish()

    # The demo plant, moved to free ports.
    work = tempfile.mkdtemp(prefix="gridscada-interop-sim-")
    sim = None
    log_path = os.path.join(work, "sim.log")
    try:
        files = glob.glob(os.path.join(root, "tags", "*.toml"))
        text = {f: open(f).read() for f in files}
        configured = sorted({int(p) for t in text.values() for p in re.findall(r'"127\.0\.0\.1:(\d+)"', t)})
        moved = dict(zip(configured, free_ports(len(configured))))
        for f, t in text.items():
            t = re.sub(r'"127\.0\.0\.1:(\d+)"', lambda m: f'"127.0.0.1:{moved[int(m.group(1))]}"', t)
            with open(os.path.join(work, os.path.basename(f)), "w") as out:
                out.write(t)
        ports = {}
        for f, t in text.items():
            for name, port in re.findall(r'\[\[device\]\]\s*\nname = "([^"]+)"(?:.|\n)*?address = "127\.0\.0\.1:(\d+)"', t):
                ports[name] = moved[int(port)]
        ports["SS1"] = ports["SS1.IO1"]
        ports["CSS1"] = ports["CSS1.IO1"]
        need = ["SS1", "CSS1", "MG.PV1", "MG.WT1", "MG.BESS1", "MG.DG1", "MG.Load"]
        if not check(all(n in ports for n in need), "demo plant devices found in tags/*.toml", str(ports)):
            finish()

        log = open(log_path, "w")
        sim = subprocess.Popen([binary, "sim", "--config", os.path.join(work, "gridscada.toml")],
                               cwd=work, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        up = wait_for(lambda: sim.poll() is None and all(port_open(ports[n]) for n in need), 30)
        if not check(up, "gridscada sim serves every device on its configured port",
                     f"exit status {sim.poll()}; log:\n" + open(log_path).read()[-2000:]):
            finish()

        try:
            pymodbus_checks(ports)
        except ImportError as e:
            check(False, "pymodbus importable", f"{e}; pip install -r tests/requirements.txt")
        if shutil.which("mbpoll"):
            mbpoll_checks(ports)
        else:
            check(False, "mbpoll installed", "mbpoll not found (apt-get install mbpoll)")
        check(sim.poll() is None, "gridscada sim still running after the clients",
              open(log_path).read()[-2000:])
    finally:
        if sim is not None and sim.poll() is None:
            # run_standalone stops on Ctrl-C (SIGINT).
            os.killpg(sim.pid, signal.SIGINT)
            try:
                sim.wait(5)
            except subprocess.TimeoutExpired:
                os.killpg(sim.pid, signal.SIGKILL)
                sim.wait()
        shutil.rmtree(work, ignore_errors=True)
    finish()


if __name__ == "__main__":
    main()
