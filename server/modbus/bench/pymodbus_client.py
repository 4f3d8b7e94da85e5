#!/usr/bin/env python3
"""Benchmark peer: pymodbus's async TCP client, one connection.

Sequential reads of 125 holding registers (function 03) from address 0, one
request in flight, for a bounded time and count; every reply is checked.
Run by `cargo run --release -p gridscada-modbus --example bench` against the
same in-process server as gridscada's poller.

Usage: pymodbus_client.py HOST PORT UNIT SECONDS [MAX_REQUESTS]
Prints one JSON line: client, requests, seconds, requests_per_s, registers_per_s.
"""

import asyncio
import json
import sys
import time

import pymodbus
from pymodbus.client import AsyncModbusTcpClient

REGISTERS = 125
WARM_UP = 50


async def main(host, port, unit, seconds, max_requests):
    client = AsyncModbusTcpClient(host, port=port, timeout=2, retries=0)
    if not await client.connect():
        print(f"pymodbus: cannot connect to {host}:{port}", file=sys.stderr)
        return 1

    async def read():
        r = await client.read_holding_registers(0, count=REGISTERS, slave=unit)
        if r.isError() or len(r.registers) != REGISTERS:
            raise RuntimeError(f"bad reply: {r}")

    try:
        for _ in range(WARM_UP):
            await read()
        n = 0
        t0 = time.perf_counter()
        deadline = t0 + seconds
        while n < max_requests and time.perf_counter() < deadline:
            await read()
            n += 1
        secs = time.perf_counter() - t0
    finally:
        client.close()
    print(json.dumps({
        "client": f"pymodbus {pymodbus.__version__} async",
        "requests": n,
        "seconds": secs,
        "requests_per_s": n / secs,
        "registers_per_s": n * REGISTERS / secs,
    }))
    return 0


if __name__ == "__main__":
    if len(sys.argv) not in (5, 6):
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    host, port, unit, seconds = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
    cap = int(sys.argv[5]) if len(sys.argv) == 6 else 10_000_000
    sys.exit(asyncio.run(main(host, port, unit, seconds, cap)))
