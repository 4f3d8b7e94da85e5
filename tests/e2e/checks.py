"""What the telecontrol end-to-end harnesses (iec104_test.py, dnp3_test.py,
sim_stations_test.py) share: one line per check ("ok"/"FAIL") with the
counts for the summary, notes for the record, a free loopback port, and a
bounded wait on a condition."""

import socket
import time

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
