"""Holds a wss:// connection to /api/live open across a certificate reload.

Usage: tls_live.py URL CAFILE COOKIE ORIGIN READY_FILE GO_FILE

Connects (verifying the server against CAFILE), waits for the hello and a
heartbeat, creates READY_FILE, then waits for GO_FILE (the test reloads the
certificate meanwhile) and requires the same connection to carry a client
message and two more heartbeats. Exit 0 on success, 1 with a reason.
"""

import asyncio
import json
import os
import ssl
import sys

import websockets


async def main() -> int:
    url, cafile, cookie, origin, ready, go = sys.argv[1:7]
    ctx = ssl.create_default_context(cafile=cafile)
    async with websockets.connect(
        url,
        ssl=ctx,
        additional_headers={"Cookie": cookie},
        origin=origin,
        open_timeout=10,
    ) as ws:
        hello = json.loads(await asyncio.wait_for(ws.recv(), 10))
        if hello.get("type") != "hello":
            print(f"tls_live: first message is not hello: {hello}")
            return 1
        await wait_for_type(ws, "heartbeat")
        open(ready, "w").close()
        for _ in range(600):
            if os.path.exists(go):
                break
            # Keep reading so the server's queue never fills.
            try:
                await asyncio.wait_for(ws.recv(), 0.1)
            except asyncio.TimeoutError:
                pass
        else:
            print("tls_live: no go signal within 60 s")
            return 1
        await ws.send(json.dumps({"visible": True}))
        for _ in range(2):
            await wait_for_type(ws, "heartbeat")
        print(f"tls_live: the connection opened before the reload still works (user {hello.get('user')})")
        return 0


async def wait_for_type(ws, kind: str) -> None:
    for _ in range(100):
        msg = json.loads(await asyncio.wait_for(ws.recv(), 10))
        if msg.get("type") == kind:
            return
    raise RuntimeError(f"no {kind} message")


if __name__ == "__main__":
    try:
        sys.exit(asyncio.run(main()))
    except Exception as e:  # the reason, not a traceback, for the test log
        print(f"tls_live: {type(e).__name__}: {e}")
        sys.exit(1)
