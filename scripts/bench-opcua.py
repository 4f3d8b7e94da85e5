"""OPC UA benchmark: reads and subscription throughput of gridscada's OPC UA
server, with the Python asyncua client, and the same reads against
asyncua's own server (the peer) holding as many variables.

Usage (the release binary, the test venv's python):
  target/test-venv/bin/python scripts/bench-opcua.py [--bin target/release/gridscada] [--seconds 10]

It starts `gridscada demo --opcua PORT` (the embedded plant) and an asyncua
server with one Double variable per demo tag, on loopback, both on the
`none` endpoint (the cost measured is the server's, not the cipher's), and
prints a Markdown table.
"""

import argparse
import asyncio
import json
import os
import socket
import subprocess
import tempfile
import time
import urllib.request

from asyncua import Client, Server, ua


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def cpu_seconds(pid):
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


async def read_rate(client, nodes, seconds, batch):
    """Values read per second, in Read requests of `batch` nodes, one
    request in flight."""
    params = []
    for i in range(0, len(nodes), batch):
        p = ua.ReadParameters()
        for n in nodes[i : i + batch]:
            rv = ua.ReadValueId()
            rv.NodeId = n.nodeid
            rv.AttributeId = ua.AttributeIds.Value
            p.NodesToRead.append(rv)
        params.append(p)
    values = requests = 0
    end = time.perf_counter() + seconds
    lat = []
    while time.perf_counter() < end:
        for p in params:
            t = time.perf_counter()
            out = await client.uaclient.read(p)
            lat.append(time.perf_counter() - t)
            values += len(out)
            requests += 1
    lat.sort()
    return values / seconds, requests / seconds, lat[len(lat) // 2], lat[int(len(lat) * 0.99)]


async def subscription_rate(client, nodes, seconds):
    class H:
        n = 0
        delays = []

        def datachange_notification(self, node, val, data):
            self.n += 1
            st = data.monitored_item.Value.SourceTimestamp
            if st:
                self.delays.append(time.time() - st.timestamp())

    h = H()
    sub = await client.create_subscription(100, h)
    await sub.subscribe_data_change(nodes, queuesize=1)
    await asyncio.sleep(2)
    h.n, h.delays = 0, []
    await asyncio.sleep(seconds)
    n, delays = h.n, sorted(h.delays)
    await sub.delete()
    p50 = delays[len(delays) // 2] if delays else float("nan")
    p99 = delays[int(len(delays) * 0.99)] if delays else float("nan")
    return n / seconds, p50, p99


async def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/gridscada")
    ap.add_argument("--seconds", type=float, default=10.0)
    args = ap.parse_args()
    tmp = tempfile.mkdtemp()
    http, port = free_port(), free_port()
    proc = subprocess.Popen(
        [args.bin, "demo", "--http", f"127.0.0.1:{http}", "--data", f"{tmp}/data", "--opcua", str(port)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    rows = []
    try:
        for _ in range(150):
            try:
                if b'"ok"' in urllib.request.urlopen(f"http://127.0.0.1:{http}/healthz", timeout=2).read():
                    break
            except Exception:
                pass
            time.sleep(0.2)
        creds = {}
        for line in open(f"{tmp}/data/credentials.txt"):
            p = line.split()
            if len(p) >= 3:
                creds[p[0]] = (p[1], p[2])
        user, password = creds["administrator"]
        c = Client(f"opc.tcp://127.0.0.1:{port}/", timeout=30)
        c.set_user(user)
        c.set_password(password)
        async with c:
            ns = await c.get_namespace_index("urn:gridscada:tags")
            root = c.get_node(ua.NodeId(0, ns))
            nodes = []

            async def walk(n):
                for ch in await n.get_children(refs=ua.ObjectIds.Organizes):
                    cls = await ch.read_node_class()
                    if cls == ua.NodeClass.Variable:
                        nodes.append(ch)
                    else:
                        await walk(ch)

            await walk(root)
            count = len(nodes)
            cpu0, t0 = cpu_seconds(proc.pid), time.perf_counter()
            v_all, r_all, p50_all, p99_all = await read_rate(c, nodes, args.seconds, count)
            cpu_all = (cpu_seconds(proc.pid) - cpu0) / (time.perf_counter() - t0)
            cpu0, t0 = cpu_seconds(proc.pid), time.perf_counter()
            v_one, r_one, p50_one, p99_one = await read_rate(c, nodes[:1], args.seconds, 1)
            cpu_one = (cpu_seconds(proc.pid) - cpu0) / (time.perf_counter() - t0)
            rows.append(("gridscada (async-opcua)", count, v_all, r_all, p50_all, p99_all, cpu_all, r_one, p50_one, p99_one, cpu_one))
            cpu0, t0 = cpu_seconds(proc.pid), time.perf_counter()
            n_rate, d50, d99 = await subscription_rate(c, nodes, args.seconds)
            cpu_sub = (cpu_seconds(proc.pid) - cpu0) / (time.perf_counter() - t0)
    finally:
        proc.terminate()
        proc.wait(timeout=30)

    # The peer: asyncua's own server, as many Double variables, in this
    # process's event loop? No: in a child process, so that client and
    # server do not share one interpreter.
    peer_port = free_port()
    peer = subprocess.Popen(
        [os.sys.executable, __file__, "--peer-server", str(peer_port), str(count)],
        stdout=subprocess.PIPE,
    )
    try:
        assert peer.stdout.readline().strip() == b"ready"
        c = Client(f"opc.tcp://127.0.0.1:{peer_port}/", timeout=30)
        async with c:
            ns = await c.get_namespace_index("urn:bench")
            folder = c.get_node(ua.NodeId("Tags", ns))
            nodes = await folder.get_children()
            cpu0, t0 = cpu_seconds(peer.pid), time.perf_counter()
            v_all, r_all, p50_all, p99_all = await read_rate(c, nodes, args.seconds, len(nodes))
            cpu_all = (cpu_seconds(peer.pid) - cpu0) / (time.perf_counter() - t0)
            cpu0, t0 = cpu_seconds(peer.pid), time.perf_counter()
            v_one, r_one, p50_one, p99_one = await read_rate(c, nodes[:1], args.seconds, 1)
            cpu_one = (cpu_seconds(peer.pid) - cpu0) / (time.perf_counter() - t0)
            rows.append(("asyncua server (Python)", len(nodes), v_all, r_all, p50_all, p99_all, cpu_all, r_one, p50_one, p99_one, cpu_one))
    finally:
        peer.terminate()
        peer.wait(timeout=30)

    print("| server | tags | values/s (all tags per Read) | Reads/s | p50 | p99 | server CPU | single-value Reads/s | p50 | p99 | server CPU |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(
            f"| {r[0]} | {r[1]} | {r[2]:,.0f} | {r[3]:,.0f} | {r[4]*1000:.1f} ms | {r[5]*1000:.1f} ms | {r[6]*100:.0f} % "
            f"| {r[7]:,.0f} | {r[8]*1000:.2f} ms | {r[9]*1000:.2f} ms | {r[10]*100:.0f} % |"
        )
    print()
    print(
        f"Subscription (every tag monitored, 100 ms publishing): {n_rate:,.0f} notifications/s, "
        f"delay from the reading's source timestamp p50 {d50*1000:.0f} ms, p99 {d99*1000:.0f} ms, "
        f"gridscada CPU {cpu_sub*100:.0f} % (the whole demo: simulators, poller, historian)"
    )


def peer_server(port, count):
    async def run():
        s = Server()
        await s.init()
        s.set_endpoint(f"opc.tcp://127.0.0.1:{port}/")
        s.set_security_policy([ua.SecurityPolicyType.NoSecurity])
        ns = await s.register_namespace("urn:bench")
        folder = await s.nodes.objects.add_folder(ua.NodeId("Tags", ns), "Tags")
        for i in range(count):
            await folder.add_variable(ua.NodeId(f"T{i}", ns), f"T{i}", float(i))
        async with s:
            print("ready", flush=True)
            while True:
                await asyncio.sleep(3600)

    asyncio.run(run())


if __name__ == "__main__":
    import sys

    if len(sys.argv) >= 4 and sys.argv[1] == "--peer-server":
        peer_server(int(sys.argv[2]), int(sys.argv[3]))
    else:
        asyncio.run(main())
