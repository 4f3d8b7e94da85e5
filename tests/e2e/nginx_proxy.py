"""gridscada behind Debian's nginx, under a sub-path (tests/e2e/nginx.sh).

The demo plant is served with base_path = "/scada", trusted_proxies =
["127.0.0.1/32"] and public_origin = nginx's origin; nginx (started from a
temp dir) proxies /scada/ to it, rewriting Host, setting X-Forwarded-For
and X-Forwarded-Proto, clearing Forwarded and passing the WebSocket upgrade
headers. Through nginx: the HMI
loads under /scada/, a login with the browser's Origin works, live pushes
arrive over the WebSocket, a tag write is confirmed, and failed logins lock
out only the real client (curl --interface 127.0.0.2 vs 127.0.0.3). Straight
to gridscada from an untrusted address, a forged X-Forwarded-For is ignored.
Forged Forwarded and X-Forwarded-For headers sent through nginx (a new
address on every try, also from 127.0.0.1, the proxy's own address) neither
escape the login lockout nor reach the event log, and do not open
/metrics: a second server (`serve`, where /metrics is not open as in
`demo`) with metrics_token and a metrics_allow address the client forges.
nginx's `location /scada/` block is the one docs/REVERSE_PROXY.md shows,
read from it.
nginx also terminates HTTPS, with a certificate from `gridscada cert
self-signed`, on the public origin: over it, a login gets a Secure cookie,
the live socket (wss) pushes, and a write is confirmed.

Usage: nginx_proxy.py GRIDSCADA_BIN REPO_ROOT. Prints one PASS/FAIL line per
check and "N passed, M failed" last.
"""

import asyncio
import json
import os
import shutil
import signal
import socket
import ssl
import subprocess
import sys
import tempfile
import textwrap
import time

import websockets

BIN, ROOT = sys.argv[1], sys.argv[2]
results = []


def check(name, ok, detail=""):
    results.append(bool(ok))
    print(("PASS " if ok else "FAIL ") + name + ("" if ok else f": {detail}"), flush=True)
    return ok


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def curl(url, *, method="GET", body=None, iface=None, headers=(), cookie=None, cacert=None):
    """One request with Debian's curl; (status, headers lower-cased, body)."""
    args = ["curl", "-sS", "--max-time", "30", "-D", "-", "-o", "-", "-X", method, url]
    if cacert:
        args += ["--cacert", cacert]
    if iface:
        args += ["--interface", iface]
    for h in headers:
        args += ["-H", h]
    if cookie:
        args += ["-H", f"Cookie: {cookie}"]
    if body is not None:
        args += ["-H", "Content-Type: application/json", "--data-binary", json.dumps(body)]
    out = subprocess.run(args, capture_output=True, timeout=40).stdout
    head, _, payload = out.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    status = int(lines[0].split()[1]) if lines and lines[0].startswith("HTTP/") else 0
    hdrs = {}
    for line in lines[1:]:
        k, _, v = line.partition(":")
        hdrs.setdefault(k.strip().lower(), []).append(v.strip())
    return status, hdrs, payload


def wait_http(url, proc, what, seconds=60):
    deadline = time.time() + seconds
    while time.time() < deadline:
        if proc.poll() is not None:
            return False
        try:
            if curl(url)[0] == 200:
                return True
        except subprocess.TimeoutExpired:
            pass
        time.sleep(0.2)
    return False


NGINX_CONF = """
worker_processes 1;
daemon off;
pid {tmp}/nginx.pid;
error_log {tmp}/nginx-error.log info;
events {{ worker_connections 256; }}
http {{
    access_log {tmp}/nginx-access.log;
    client_body_temp_path {tmp}/nginx-body;
    proxy_temp_path {tmp}/nginx-proxy;
    fastcgi_temp_path {tmp}/nginx-fastcgi;
    uwsgi_temp_path {tmp}/nginx-uwsgi;
    scgi_temp_path {tmp}/nginx-scgi;
    map $http_upgrade $connection_upgrade {{
        default upgrade;
        ''      close;
    }}
    server {{
        listen 127.0.0.1:{nginx_port};
{demo_location}
    }}
    # The public origin: nginx terminates HTTPS and tells gridscada so
    # (X-Forwarded-Proto https).
    server {{
        listen 127.0.0.1:{tls_port} ssl;
        ssl_certificate {cert};
        ssl_certificate_key {key};
{demo_location}
    }}
    # The server whose /metrics is closed.
    server {{
        listen 127.0.0.1:{metrics_nginx_port};
{metrics_location}
    }}
}}
"""


def documented_location(gs_port):
    """The `location /scada/ {...}` block of docs/REVERSE_PROXY.md's nginx
    example, proxying to `gs_port`, with the test's own Host (one gridscada
    cannot compare an Origin with) and no temp files (started as root, the
    workers run as nobody). None if the doc no longer has the lines."""
    with open(os.path.join(ROOT, "docs", "REVERSE_PROXY.md")) as f:
        doc = f.read()
    try:
        example = doc.split("```nginx\n", 1)[1].split("```", 1)[0]
        start = example.index("    location /scada/ {")
        end = example.index("\n    }\n", start) + len("\n    }")
    except (IndexError, ValueError):
        return None
    block = example[start:end]
    for line, ours in (("proxy_pass http://127.0.0.1:8080;", f"proxy_pass http://127.0.0.1:{gs_port};"),
                       ("proxy_set_header Host $host;", "proxy_set_header Host backend.internal;")):
        if block.count(line) != 1:
            return None
        block = block.replace(line, ours)
    return textwrap.indent(block[: -len("}")] + "    proxy_max_temp_file_size 0;\n    }", "    ")


def main():
    tmp = tempfile.mkdtemp(prefix="gridscada-nginx-")
    os.chmod(tmp, 0o755)
    procs = []
    try:
        run(tmp, procs)
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
                try:
                    p.wait(20)
                except subprocess.TimeoutExpired:
                    p.kill()
        if not all(results) or not results:
            for log in ("server.log", "metrics-server.log", "nginx-error.log"):
                path = os.path.join(tmp, log)
                if os.path.exists(path):
                    print(f"--- {log} (last lines)")
                    with open(path, errors="replace") as f:
                        print("".join(f.readlines()[-30:]))
        shutil.rmtree(tmp, ignore_errors=True)
    passed = sum(results)
    failed = len(results) - passed
    if not results:
        failed = 1
    print(f"{passed} passed, {failed} failed")
    sys.exit(1 if failed else 0)


def run(tmp, procs):
    nginx = shutil.which("nginx") or "/usr/sbin/nginx"
    if not os.path.exists(nginx):
        check("setup: Debian's nginx is installed", False, "no nginx (apt-get install nginx)")
        return
    gs_port, nginx_port, tls_port = free_port(), free_port(), free_port()
    # Browsers come by HTTPS (the public origin); the plain listener is for
    # the checks that need no TLS.
    public = f"https://127.0.0.1:{tls_port}"
    plain = f"http://127.0.0.1:{nginx_port}"
    certs = os.path.join(tmp, "certs")
    made = subprocess.run([BIN, "cert", "self-signed", "--host", "127.0.0.1", "--out", certs],
                          capture_output=True, text=True, timeout=60)
    if not check("setup: gridscada cert self-signed", made.returncode == 0, made.stderr):
        return
    cert, key = os.path.join(certs, "cert.pem"), os.path.join(certs, "key.pem")
    # The demo plant, with the reverse-proxy settings.
    plant = os.path.join(tmp, "plant")
    shutil.copytree(os.path.join(ROOT, "tags"), plant)
    main_file = os.path.join(plant, "gridscada.toml")
    with open(main_file) as f:
        text = f.read()
    settings = (
        "[server]\n"
        f'public_origin = "{public}"\n'
        'trusted_proxies = ["127.0.0.1/32"]\n'
        'base_path = "/scada"\n'
        'allowed_hosts = ["backend.internal"]\n'
    )
    assert "[server]\n" in text
    with open(main_file, "w") as f:
        f.write(text.replace("[server]\n", settings, 1))
    data = os.path.join(tmp, "data")
    log = open(os.path.join(tmp, "server.log"), "w")
    # Loopback only: the untrusted clients below are 127.0.0.2 and up.
    gs = subprocess.Popen(
        [BIN, "demo", "--config", plant, "--http", f"127.0.0.1:{gs_port}", "--data", data],
        stdout=log, stderr=subprocess.STDOUT,
    )
    procs.append(gs)
    direct = f"http://127.0.0.1:{gs_port}/scada"
    if not check("setup: gridscada demo answers under /scada", wait_http(f"{direct}/healthz", gs, "gridscada")):
        return
    # A second server, `serve`: its /metrics wants the token, except from
    # an address in metrics_allow (one the clients below forge).
    ms_port, metrics_nginx_port = free_port(), free_port()
    ms = start_metrics_server(tmp, ms_port)
    procs.append(ms)
    if not check("setup: gridscada serve answers under /scada",
                 wait_http(f"http://127.0.0.1:{ms_port}/scada/healthz", ms, "gridscada serve")):
        return
    demo_location = documented_location(gs_port)
    metrics_location = documented_location(ms_port)
    if not check("setup: docs/REVERSE_PROXY.md shows the nginx location block",
                 demo_location and metrics_location, "no `location /scada/` with proxy_pass and Host lines"):
        return
    with open(os.path.join(tmp, "nginx.conf"), "w") as f:
        f.write(NGINX_CONF.format(tmp=tmp, nginx_port=nginx_port, tls_port=tls_port, cert=cert, key=key,
                                  metrics_nginx_port=metrics_nginx_port, demo_location=demo_location,
                                  metrics_location=metrics_location))
    ng = subprocess.Popen(
        [nginx, "-p", tmp, "-c", os.path.join(tmp, "nginx.conf")],
        stdout=subprocess.DEVNULL, stderr=open(os.path.join(tmp, "nginx-stderr.log"), "w"),
    )
    procs.append(ng)
    via = f"{plain}/scada"
    if not check("setup: nginx proxies /scada/", wait_http(f"{via}/healthz", ng, "nginx")):
        return
    accounts = {}
    with open(os.path.join(data, "credentials.txt")) as f:
        for line in f:
            parts = line.split()
            if len(parts) == 3:
                accounts[parts[0]] = (parts[1], parts[2])
    op_user, op_pass = accounts["operator"]
    admin_user, admin_pass = accounts["administrator"]
    origin = f"Origin: {public}"

    # The HMI under the sub-path.
    st, h, body = curl(f"{via}/")
    check("the HMI page loads under /scada/ through nginx", st == 200 and b'src="js/app.js"' in body, st)
    st, _, body = curl(f"{via}/js/api.js")
    check("its modules load under /scada/", st == 200 and b"import.meta.url" in body, st)
    st, h, _ = curl(direct)
    check("/scada is redirected to /scada/", st == 308 and h.get("location") == ["/scada/"], (st, h.get("location")))
    st, _, _ = curl(f"http://127.0.0.1:{gs_port}/api/session")
    check("nothing is served outside the base path", st == 404, st)
    st, _, body = curl(f"{via}/api/openapi.json")
    check("the OpenAPI document names the base path", st == 200 and json.loads(body)["servers"] == [{"url": "/scada/"}], body[:200])

    # Log in as a browser on the public origin would.
    st, h, body = curl(f"{via}/api/session", method="POST", body={"username": op_user, "password": op_pass},
                       iface="127.0.0.2", headers=[origin])
    cookies = h.get("set-cookie", [])
    check("login through nginx with the public Origin", st == 200 and cookies, (st, body[:200]))
    if not cookies:
        return
    cookie = cookies[0].split(";")[0]
    attrs = [a.strip() for a in cookies[0].split(";")]
    check("the session cookie's Path is the base path", "Path=/scada" in attrs, cookies[0])
    check("no Secure flag over plain http", "Secure" not in attrs, cookies[0])
    st, _, body = curl(f"{via}/api/session", cookie=cookie)
    check("the session works through nginx", st == 200 and json.loads(body).get("user") == op_user, body[:200])
    st, _, body = curl(f"{via}/api/session", method="POST", body={"username": op_user, "password": op_pass},
                       headers=[f"Origin: http://backend.internal"])
    check("an Origin other than the public origin is refused", st == 403, (st, body[:200]))

    # Live push and a confirmed write through nginx.
    asyncio.run(live_and_write(via, public, cookie))

    # Throttling per real client: 127.0.0.2 locked out, 127.0.0.3 not.
    url = f"{via}/api/session"
    locked = fail_logins(url, op_user, iface="127.0.0.2", headers=[origin])
    check("failed logins through nginx lock out their client (127.0.0.2)", locked, "never throttled")
    st, _, _ = curl(url, method="POST", body={"username": op_user, "password": op_pass}, iface="127.0.0.2", headers=[origin])
    check("127.0.0.2 cannot log in while locked, even with the right password", st == 429, st)
    st, _, _ = curl(url, method="POST", body={"username": op_user, "password": op_pass}, iface="127.0.0.3", headers=[origin])
    check("127.0.0.3 behind the same proxy still logs in", st == 200, st)

    # A client cannot pose as another by sending its own X-Forwarded-For:
    # through nginx, nginx's own word on the client replaces it ...
    forged = iter(f"X-Forwarded-For: 10.66.0.{i}" for i in range(1, 250))
    locked = fail_logins(url, admin_user, iface="127.0.0.7", headers=[origin], forged=forged)
    check("a forged X-Forwarded-For through nginx does not escape the lockout", locked, "never throttled")
    # ... and straight to gridscada from an untrusted address, it is ignored.
    durl = f"{direct}/api/session"
    locked = fail_logins(durl, admin_user, iface="127.0.0.5", headers=[origin], forged=forged)
    check("a forged X-Forwarded-For straight from 127.0.0.5 is ignored", locked, "never throttled")
    st, _, _ = curl(durl, method="POST", body={"username": admin_user, "password": admin_pass},
                    iface="127.0.0.5", headers=[origin, next(forged)])
    check("127.0.0.5 stays locked whatever address it claims", st == 429, st)
    st, h, _ = curl(durl, method="POST", body={"username": op_user, "password": op_pass},
                    iface="127.0.0.6", headers=[origin, "X-Forwarded-Proto: https"])
    sc = h.get("set-cookie", [""])[0]
    check("X-Forwarded-Proto from an untrusted client gives no Secure cookie", st == 200 and "Secure" not in sc, (st, sc))
    st, h, _ = curl(durl, method="POST", body={"username": op_user, "password": op_pass},
                    headers=[origin, "X-Forwarded-Proto: https", "X-Forwarded-For: 127.0.0.8"])
    sc = h.get("set-cookie", [""])[0]
    check("proto=https from the trusted proxy gives a Secure cookie", st == 200 and "; Secure" in sc, (st, sc))

    # Forged headers through nginx, a new address on every try: the
    # client's own Forwarded (nginx passes it through) ...
    forged = iter(f"Forwarded: for=10.88.0.{i}" for i in range(1, 250))
    locked = fail_logins(url, "forger-fwd", iface="127.0.0.10", headers=[origin], forged=forged)
    check("a forged Forwarded through nginx does not escape the lockout (127.0.0.10)", locked, "never throttled")
    # ... and X-Forwarded-For from a client on the proxy's own address, which
    # is a trusted proxy: nginx must replace the header, not append to it.
    forged = iter(f"X-Forwarded-For: 10.99.0.{i}" for i in range(1, 250))
    locked = fail_logins(url, "forger-xff", iface="127.0.0.1", headers=[origin], forged=forged)
    check("a forged X-Forwarded-For from the proxy's own address does not escape the lockout", locked,
          "never throttled")
    sup_user, sup_pass = accounts["supervisor"]
    st, _, body = curl(url, method="POST", body={"username": sup_user, "password": sup_pass},
                       iface="127.0.0.11", headers=[origin, "Forwarded: for=8.8.8.8", "X-Forwarded-For: 8.8.4.4"])
    check("a login with forged headers through nginx works (127.0.0.11)", st == 200, (st, body[:200]))
    metrics_checks(f"http://127.0.0.1:{metrics_nginx_port}/scada/metrics")

    # The audit trail names the real clients, never the proxy.
    st, h, body = curl(f"{via}/api/session", method="POST", body={"username": admin_user, "password": admin_pass},
                       iface="127.0.0.9", headers=[origin])
    admin_cookie = h.get("set-cookie", [""])[0].split(";")[0]
    st, _, body = curl(f"{via}/api/events?limit=500", cookie=admin_cookie)
    texts = [e.get("message", "") for e in json.loads(body).get("events", [])] if st == 200 else []
    logins = [t for t in texts if "login" in t or "logged in" in t]
    check("events record the real client behind nginx",
          any("from 127.0.0.2" in t for t in logins) and any("logged in from 127.0.0.3" in t for t in logins),
          logins[:5] or (st, body[:200]))
    check("events record the untrusted peer, not its forged address",
          any("from 127.0.0.5" in t for t in logins) and not any("10.66.0." in t for t in logins), logins[:8])
    # forger-xff really is on 127.0.0.1 (nginx's own address).
    others = [t for t in logins if "'forger-xff'" not in t]
    check("no login is recorded as from the proxy",
          not any("from 127.0.0.1:" in t or t.endswith("from 127.0.0.1") for t in others), others[:8])
    forgers = [t for t in logins if "'forger-" in t]
    check("forged Forwarded through nginx: failed logins recorded from the real client",
          forgers and any("'forger-fwd' from 127.0.0.10:" in t for t in forgers), forgers[:4])
    check("forged X-Forwarded-For through nginx: failed logins recorded from the real client",
          any("'forger-xff' from 127.0.0.1:" in t for t in forgers), forgers[:4])
    check("a login with forged headers is recorded from its real client",
          any(t.endswith(f"{sup_user} logged in from 127.0.0.11") for t in logins), logins[:8])
    check("no forged address reaches the event log",
          not any(a in t for t in logins for a in ("10.88.0.", "10.99.0.", "8.8.8.8", "8.8.4.4")),
          [t for t in logins if "10.88.0." in t or "10.99.0." in t or "8.8." in t][:4])

    # HTTPS at nginx, as a site runs it: the public origin.
    https_checks(f"{public}/scada", public, cert, op_user, op_pass)


def start_metrics_server(tmp, port):
    """`gridscada serve` on a one-device plant under /scada behind the same
    kind of proxy, /metrics closed but to its token and 10.77.0.1."""
    plant = os.path.join(tmp, "metrics-plant")
    os.makedirs(plant)
    with open(os.path.join(plant, "gridscada.toml"), "w") as f:
        f.write('tag_files = ["tags.toml"]\n'
                "[server]\n"
                'trusted_proxies = ["127.0.0.1/32"]\n'
                'base_path = "/scada"\n'
                'allowed_hosts = ["backend.internal"]\n'
                'metrics_token = "scrape-secret"\n'
                'metrics_allow = ["10.77.0.1"]\n')
    with open(os.path.join(plant, "tags.toml"), "w") as f:
        # Nothing listens there: the device is simply down.
        f.write('[[device]]\nname = "D1"\nprotocol = "tcp"\naddress = "127.0.0.1:9"\n')
    log = open(os.path.join(tmp, "metrics-server.log"), "w")
    return subprocess.Popen(
        [BIN, "serve", "--config", plant, "--http", f"127.0.0.1:{port}", "--data", os.path.join(tmp, "metrics-data")],
        stdout=log, stderr=subprocess.STDOUT,
    )


def metrics_checks(url):
    """/metrics through nginx: a forged header naming the metrics_allow
    address opens nothing; the token does."""
    st, _, body = curl(url, iface="127.0.0.12")
    check("/metrics through nginx wants the token", st == 401, (st, body[:200]))
    for iface, forged in (("127.0.0.12", "Forwarded: for=10.77.0.1"),
                          ("127.0.0.12", "X-Forwarded-For: 10.77.0.1"),
                          ("127.0.0.1", "X-Forwarded-For: 10.77.0.1"),
                          ("127.0.0.1", "Forwarded: for=10.77.0.1")):
        st, _, body = curl(url, iface=iface, headers=[forged])
        check(f"/metrics through nginx: '{forged}' from {iface} does not open it", st == 401, (st, body[:200]))
    st, _, body = curl(url, iface="127.0.0.12", headers=["Authorization: Bearer scrape-secret"])
    check("/metrics through nginx with the token", st == 200 and b"gridscada_build_info" in body, (st, body[:200]))


def https_checks(via, public, cert, user, password):
    st, _, body = curl(f"{via}/api/session", method="POST", body={"username": user, "password": password},
                       iface="127.0.0.3", headers=[f"Origin: {public}"], cacert=cert)
    check("HTTPS through nginx: login", st == 200, (st, body[:200]))
    st, h, _ = curl(f"{via}/api/session", method="POST", body={"username": user, "password": password},
                    iface="127.0.0.4", headers=[f"Origin: {public}"], cacert=cert)
    sc = h.get("set-cookie", [""])[0]
    attrs = [a.strip() for a in sc.split(";")]
    check("HTTPS through nginx: the session cookie is Secure, Path /scada", st == 200 and "Secure" in attrs and "Path=/scada" in attrs, sc)
    cookie = sc.split(";")[0]
    st, _, _ = curl(f"{via}/api/session", cacert=None)
    check("HTTPS through nginx: a client that does not trust the certificate is refused", st == 0, st)
    asyncio.run(https_live_and_write(via, public, cert, cookie))


async def https_live_and_write(via, public, cert, cookie):
    tag = "SS1.Zone4.Cmd"
    tls = ssl.create_default_context(cafile=cert)
    try:
        async with websockets.connect(via.replace("https://", "wss://") + "/api/live", origin=public, ssl=tls,
                                      additional_headers={"Cookie": cookie}, open_timeout=15) as ws:
            hello = json.loads(await asyncio.wait_for(ws.recv(), 10))
            check("HTTPS through nginx: the live socket opens (wss)", hello.get("type") == "hello", hello)
            await ws.send(json.dumps({"subscribe": {"tags": [tag]}, "visible": True}))
            seen = await next_value(ws, tag, None)
            check(f"HTTPS through nginx: a live push of {tag}", seen is not None, "no push within 15 s")
            new = not seen if isinstance(seen, bool) else False
            st, _, body = await asyncio.to_thread(
                curl, f"{via}/api/tags/{tag}/write", method="POST", body={"value": new},
                iface="127.0.0.4", headers=[f"Origin: {public}"], cookie=cookie, cacert=cert)
            out = json.loads(body) if st == 200 else {}
            check(f"HTTPS through nginx: writing {tag} = {new} is confirmed", st == 200 and out.get("value") == new, (st, body[:300]))
            pushed = await next_value(ws, tag, new)
            check("HTTPS through nginx: the confirmed value is pushed (wss)", pushed == new, pushed)
            await asyncio.to_thread(
                curl, f"{via}/api/tags/{tag}/write", method="POST", body={"value": seen},
                iface="127.0.0.4", headers=[f"Origin: {public}"], cookie=cookie, cacert=cert)
    except Exception as e:  # noqa: BLE001 - reported as a failed check
        check("HTTPS through nginx: live push and write", False, repr(e))


def fail_logins(url, user, *, iface, headers, forged=None, failures=7):
    """Wrong passwords from `iface` until `failures` are counted (each lock
    waited out), so the lock is then seconds long; whether any was refused
    as throttled (429)."""
    counted, throttled = 0, False
    deadline = time.time() + 90
    while counted < failures and time.time() < deadline:
        extra = [next(forged)] if forged else []
        st, _, _ = curl(url, method="POST", body={"username": user, "password": "wrong-password"},
                        iface=iface, headers=headers + extra)
        if st == 401:
            counted += 1
        elif st == 429:
            throttled = True
            time.sleep(0.3)
        else:
            return False
    return throttled and counted >= failures


async def live_and_write(via, public, cookie):
    ws_url = via.replace("http://", "ws://") + "/api/live"
    tag = "SS1.Zone4.Cmd"
    try:
        async with websockets.connect(ws_url, origin=public, additional_headers={"Cookie": cookie},
                                      open_timeout=15) as ws:
            hello = json.loads(await asyncio.wait_for(ws.recv(), 10))
            check("the live WebSocket opens through nginx", hello.get("type") == "hello", hello)
            await ws.send(json.dumps({"subscribe": {"tags": [tag]}, "visible": True}))
            seen = await next_value(ws, tag, None)
            check(f"a live push of {tag} arrives through nginx", seen is not None, "no push within 15 s")
            beats = 0
            deadline = time.time() + 5
            while beats < 2 and time.time() < deadline:
                m = json.loads(await asyncio.wait_for(ws.recv(), 5))
                beats += m.get("type") == "heartbeat"
            check("heartbeats keep coming over the proxied socket", beats >= 2, beats)
            new = not seen if isinstance(seen, bool) else False
            st, _, body = await asyncio.to_thread(
                curl, f"{via}/api/tags/{tag}/write", method="POST", body={"value": new},
                iface="127.0.0.2", headers=[f"Origin: {public}"], cookie=cookie)
            out = json.loads(body) if st == 200 else {}
            check(f"writing {tag} = {new} through nginx is confirmed", st == 200 and out.get("value") == new, (st, body[:300]))
            pushed = await next_value(ws, tag, new)
            check("the confirmed value is pushed over the WebSocket", pushed == new, pushed)
            # Put it back as it was.
            await asyncio.to_thread(
                curl, f"{via}/api/tags/{tag}/write", method="POST", body={"value": seen},
                iface="127.0.0.2", headers=[f"Origin: {public}"], cookie=cookie)
    except Exception as e:  # noqa: BLE001 - reported as a failed check
        check("live push and write through nginx", False, repr(e))
    try:
        async with websockets.connect(ws_url, origin="http://evil.example", additional_headers={"Cookie": cookie},
                                      open_timeout=15) as ws:
            await ws.recv()
        check("a WebSocket from another origin is refused", False, "it opened")
    except websockets.exceptions.InvalidStatus as e:
        check("a WebSocket from another origin is refused", e.response.status_code == 403, e.response.status_code)


async def next_value(ws, tag, want):
    """The next pushed value of `tag` (equal to `want` unless None)."""
    deadline = time.time() + 15
    while time.time() < deadline:
        try:
            m = json.loads(await asyncio.wait_for(ws.recv(), max(0.1, deadline - time.time())))
        except asyncio.TimeoutError:
            break
        if m.get("type") == "tags":
            for v in m.get("values", []):
                if v.get("name") == tag and (want is None or v.get("value") == want):
                    return v.get("value")
    return None


if __name__ == "__main__":
    main()
