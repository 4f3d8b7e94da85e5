"""Slow clients against a running gridscada (driven by slow_clients.sh).

An attacker holds `--slow` TCP connections that each send half a request
(`GET /healthz HTTP/1.1`, a Host, then `X-a: ` and nothing more), spread
over several loopback addresses, one of them the address the health probe
uses, and re-opens each half a second after the server closes it. Meanwhile a
probe asks /healthz every 250 ms with a 1 s deadline, and the server's RSS
is sampled. Then the attacker stops re-opening and the held connections
must be closed by the server within the header timeout.

Prints one line per check ("ok ..." / "FAIL ...") and exits 1 on any
failure.
"""

import argparse
import asyncio
import multiprocessing
import resource
import socket
import time


def rss_kib(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


class Attacker:
    def __init__(self, host, port, sources, count):
        self.host, self.port = host, port
        self.sources = sources
        self.count = count
        self.reopen = True
        self.opened = 0
        self.closed_by_server = 0
        self.lifetimes = []
        self.open_now = 0
        self.connect_errors = 0
        self.reopen_delay = 0.5

    async def one(self, source):
        while True:
            started = time.monotonic()
            try:
                reader, writer = await asyncio.open_connection(
                    self.host, self.port, local_addr=(source, 0)
                )
            except OSError:
                self.connect_errors += 1
                await asyncio.sleep(0.2)
                if not self.reopen:
                    return
                continue
            self.opened += 1
            self.open_now += 1
            try:
                writer.write(
                    f"GET /healthz HTTP/1.1\r\nHost: {self.host}\r\nX-a: ".encode()
                )
                await writer.drain()
                # Hold: read until the server closes the connection.
                while await reader.read(4096):
                    pass
            except OSError:
                pass
            finally:
                self.open_now -= 1
                self.closed_by_server += 1
                self.lifetimes.append(time.monotonic() - started)
                writer.close()
            if not self.reopen:
                return
            # The attacker keeps its connections up, re-opening each soon
            # after the server closes it.
            await asyncio.sleep(self.reopen_delay)

    def start(self):
        return [
            asyncio.create_task(self.one(self.sources[i % len(self.sources)]))
            for i in range(self.count)
        ]


def probe(host, port, source):
    """One GET /healthz over a blocking socket; its status, seconds, error."""
    started = time.monotonic()
    try:
        with socket.create_connection((host, port), timeout=1.0, source_address=(source, 0)) as s:
            s.settimeout(max(0.01, 1.0 - (time.monotonic() - started)))
            s.sendall(
                f"GET /healthz HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode()
            )
            head = b""
            while b"\r\n" not in head:
                chunk = s.recv(1024)
                if not chunk:
                    break
                head += chunk
        parts = head.split()
        status = int(parts[1]) if len(parts) > 1 else 0
        return status, time.monotonic() - started, None
    except OSError as e:
        return 0, time.monotonic() - started, repr(e)


def probe_loop(host, port, seconds, results):
    """The health probe, in a process of its own so that the attacker's
    event loop cannot delay it: every 250 ms for `seconds`."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        results.put(probe(host, port, "127.0.0.1"))
        time.sleep(0.25)
    results.put(None)


async def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--pid", type=int, required=True)
    ap.add_argument("--slow", type=int, default=1100)
    ap.add_argument("--seconds", type=float, default=25.0)
    ap.add_argument("--header-timeout", type=float, default=10.0)
    ap.add_argument("--rss-growth-mib", type=float, default=128.0)
    args = ap.parse_args()
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    host = "127.0.0.1"
    failures = 0

    def check(good, text):
        nonlocal failures
        print(("ok   " if good else "FAIL ") + text, flush=True)
        if not good:
            failures += 1

    rss_before = rss_kib(args.pid)
    # Half the slow connections from the probe's own address, the rest
    # from four others: the per-client cap and the global cap both bind.
    sources = ["127.0.0.1"] * 4 + ["127.0.0.2", "127.0.0.3", "127.0.0.4", "127.0.0.5"]
    attacker = Attacker(host, args.port, sources, args.slow)
    tasks = attacker.start()
    await asyncio.sleep(1.0)
    results = multiprocessing.Queue()
    prober = multiprocessing.Process(
        target=probe_loop, args=(host, args.port, args.seconds, results)
    )
    prober.start()
    probes = []
    rss_max = rss_before
    while True:
        rss_max = max(rss_max, rss_kib(args.pid))
        await asyncio.sleep(0.25)
        done = False
        while not results.empty():
            p = results.get()
            if p is None:
                done = True
            else:
                probes.append(p)
        if done:
            break
    prober.join()
    held_at_end = attacker.open_now
    attacker.reopen = False

    answered = [p for p in probes if p[0] == 200 and p[1] < 1.0]
    worst = max((p[1] for p in probes), default=0.0)
    check(
        len(probes) > 0 and len(answered) == len(probes),
        f"/healthz answered 200 within 1 s {len(answered)} of {len(probes)} times "
        f"while {args.slow} slow connections pressed (worst {worst * 1000:.0f} ms)"
        + "".join(f"; {p[2]}" for p in probes if p[2])[:300],
    )
    check(
        attacker.opened > args.slow,
        f"the server kept accepting: {attacker.opened} slow connections opened, "
        f"{attacker.closed_by_server} closed by the server, {held_at_end} held at the end",
    )
    growth = (rss_max - rss_before) / 1024
    check(
        growth < args.rss_growth_mib,
        f"RSS grew {growth:.1f} MiB under the attack ({rss_before / 1024:.1f} -> {rss_max / 1024:.1f} MiB; bound {args.rss_growth_mib:.0f} MiB)",
    )

    # Every connection still held must be closed by the server within the
    # header timeout (plus slack for the timer and the scheduler).
    wait = args.header_timeout + 3.0
    try:
        await asyncio.wait_for(asyncio.gather(*tasks), wait)
        check(True, f"every slow connection was closed by the server within {wait:.0f} s")
    except asyncio.TimeoutError:
        check(
            False,
            f"{attacker.open_now} slow connections still open {wait:.0f} s after the attack stopped",
        )
    longest = max(attacker.lifetimes, default=0.0)
    check(
        longest <= args.header_timeout + 3.0,
        f"no slow connection lived past the header timeout: longest {longest:.1f} s (timeout {args.header_timeout:.0f} s)",
    )
    status, secs, err = probe(host, args.port, "127.0.0.1")
    check(status == 200, f"/healthz after the attack: {status} in {secs * 1000:.0f} ms {err or ''}")
    return failures


if __name__ == "__main__":
    raise SystemExit(1 if asyncio.run(main()) else 0)
