"""Slow and idle connections against the OPC UA port (issue 36, finding 1):
connections that send nothing or half a Hello must not lock real clients
out, must be closed after the handshake timeout, and past the caps are
closed at once and counted.

Usage: opcua_slow.py URL METRICS_URL USER PASSWORD

The server's defaults: 8 connections per client address, 64 in all, 5 s
to say Hello and open the secure channel.
Prints "ok ..." / "FAIL ..." lines, then "N passed, M failed".
"""

import asyncio
import socket
import sys
import time
import urllib.request
from urllib.parse import urlparse

from asyncua import Client, ua

import opcua_client as oc
from opcua_client import check

PER_CLIENT, TOTAL, HELLO_S = 8, 64, 5


def hold(host, port, source, n):
    """n connections from the loopback address `source`, sending nothing."""
    out = []
    for _ in range(n):
        s = socket.socket()
        s.settimeout(2)
        s.bind((source, 0))
        try:
            s.connect((host, port))
        except OSError:
            s.close()
            continue
        out.append(s)
    return out


def still_open(socks):
    """The connections the server has not closed (a read would block)."""
    n = 0
    for s in socks:
        s.setblocking(False)
        try:
            data = s.recv(4096)
            # An error message before the close counts as closed once EOF follows.
            if data:
                try:
                    n += 0 if s.recv(4096) == b"" else 1
                except BlockingIOError:
                    n += 1
        except BlockingIOError:
            n += 1
        except OSError:
            pass
    return n


def wait_closed(socks, limit_s):
    end = time.monotonic() + limit_s
    while time.monotonic() < end:
        if still_open(socks) == 0:
            return True
        time.sleep(0.2)
    return still_open(socks) == 0


def refused_metric(url):
    with urllib.request.urlopen(url, timeout=10) as r:
        for line in r.read().decode().splitlines():
            if line.startswith("gridscada_opcua_connections_refused_total"):
                return float(line.rsplit(" ", 1)[1])
    return None


async def real_client(url, user, password):
    c = Client(url, timeout=5)
    c.set_user(user)
    c.set_password(password)
    t0 = time.monotonic()
    await asyncio.wait_for(c.connect(), 8)
    try:
        await c.get_node(ua.ObjectIds.Server_ServerStatus_State).read_value()
    finally:
        await c.disconnect()
    return time.monotonic() - t0


def main(url, metrics_url, user, password):
    u = urlparse(url)
    host, port = u.hostname, u.port
    before = refused_metric(metrics_url) or 0.0

    # One host opens 300 connections and says nothing.
    idle = hold(host, port, "127.0.0.2", 300)
    time.sleep(1)
    check("one address holding 300 idle connections keeps at most 8 of them",
          still_open(idle) <= PER_CLIENT, f"{still_open(idle)} still open")
    # Half a Hello on what it kept.
    for s in idle:
        try:
            s.setblocking(True)
            s.send(b"HELF\x40\x00\x00\x00\x00\x00")
        except OSError:
            pass
    try:
        took = asyncio.run(real_client(url, user, password))
        check("a real client still connects and reads meanwhile", took < 5, f"{took:.1f} s")
    except Exception as e:
        check("a real client still connects and reads meanwhile", False, repr(e))
    check(f"the idle and half-Hello connections are closed after the {HELLO_S} s handshake timeout",
          wait_closed(idle, HELLO_S + 4), f"{still_open(idle)} still open")
    after = refused_metric(metrics_url) or 0.0
    check("/metrics counts the connections refused past the cap",
          after - before >= 300 - PER_CLIENT, f"{before} -> {after}")
    for s in idle:
        s.close()

    # Many addresses: the global cap.
    spread = []
    for i in range(2, 12):
        spread += hold(host, port, f"127.0.0.{i + 10}", PER_CLIENT)
    time.sleep(1)
    check(f"{len(spread)} connections from 10 addresses: at most {TOTAL} stay open",
          still_open(spread) <= TOTAL, f"{still_open(spread)} still open")
    check("and they are closed after the handshake timeout too",
          wait_closed(spread, HELLO_S + 4), f"{still_open(spread)} still open")
    for s in spread:
        s.close()
    try:
        asyncio.run(real_client(url, user, password))
        check("then a real client connects again", True)
    except Exception as e:
        check("then a real client connects again", False, repr(e))

    print(f"{oc.passed} passed, {oc.failed} failed")
    return 1 if oc.failed else 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:5]))
