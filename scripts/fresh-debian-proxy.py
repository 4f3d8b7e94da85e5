#!/usr/bin/env python3
"""The package registries, for the fresh Debian of scripts/fresh-debian.sh.

That Debian runs in a network namespace of its own (its PostgreSQL on
127.0.0.1:5432 must not meet this machine's), which has no route out. Its apt,
pip, cargo and npm reach the registries through an HTTP proxy:

    fresh-debian-proxy.py serve SOCKET        # on the host: the proxy, on a Unix socket
    fresh-debian-proxy.py bridge PORT SOCKET  # in the namespace: 127.0.0.1:PORT to SOCKET

The proxy takes `CONNECT host:443` (HTTPS, tunnelled as is) and plain HTTP
requests in absolute form (`GET http://host/path`, as apt sends them), which
it passes to the named host unchanged: servers accept the absolute form.
"""
import asyncio
import sys


async def pipe(reader, writer):
    try:
        while data := await reader.read(65536):
            writer.write(data)
            await writer.drain()
    except (ConnectionError, asyncio.CancelledError):
        pass
    finally:
        try:
            writer.close()
        except Exception:
            pass


async def splice(r1, w1, r2, w2):
    await asyncio.gather(pipe(r1, w2), pipe(r2, w1))


async def handle_proxy(reader, writer):
    try:
        head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), 60)
        method, target, _ = head.split(b"\r\n", 1)[0].decode("latin-1").split(" ", 2)
        if method == "CONNECT":
            host, port = target.rsplit(":", 1)
            up_r, up_w = await asyncio.wait_for(asyncio.open_connection(host, int(port)), 30)
            writer.write(b"HTTP/1.1 200 Connection established\r\n\r\n")
            await writer.drain()
        elif target.startswith("http://"):
            hostport = target[len("http://"):].split("/", 1)[0]
            host, _, port = hostport.partition(":")
            up_r, up_w = await asyncio.wait_for(asyncio.open_connection(host, int(port or 80)), 30)
            up_w.write(head)
        else:
            writer.write(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n")
            writer.close()
            return
    except Exception as e:  # unreachable host, bad request: the client sees 502
        print(f"fresh-debian-proxy: {e!r}", file=sys.stderr)
        writer.write(b"HTTP/1.1 502 Bad Gateway\r\nContent-Length: 0\r\n\r\n")
        writer.close()
        return
    await splice(reader, writer, up_r, up_w)


async def main():
    if len(sys.argv) == 3 and sys.argv[1] == "serve":
        server = await asyncio.start_unix_server(handle_proxy, path=sys.argv[2])
    elif len(sys.argv) == 4 and sys.argv[1] == "bridge":
        sock = sys.argv[3]

        async def handle_bridge(reader, writer):
            try:
                up_r, up_w = await asyncio.open_unix_connection(sock)
            except OSError:
                writer.close()
                return
            await splice(reader, writer, up_r, up_w)

        server = await asyncio.start_server(handle_bridge, "127.0.0.1", int(sys.argv[2]))
    else:
        sys.exit(__doc__)
    async with server:
        await server.serve_forever()


if __name__ == "__main__":
    asyncio.run(main())
