#!/usr/bin/env python3
"""Many sites: three gridscada edge nodes (three simulated plants, each a copy
of the demo plant on its own Modbus ports, `demo --mqtt URL --mqtt-node ID`)
and one gridscada central host (`[mqtt.host]`) on one Debian mosquitto.
Run by sparkplug_sites.sh.

Checks: the central /api/tags holds every tag of every site, named
SITE.TAG, with the edges' qualities and (for discrete tags) values; kill -9
of one edge turns its tags Bad at the centre within the keep-alive and only
its tags; restarting it brings them back Good through its rebirth; a write
from the central API reaches the right site's device (the edge's own
/api/tags reads it back), answers only once confirmed, and is audited at
both ends.

Prints "N passed, M failed" last; exits non-zero on any failure.
"""

import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import sparkplug_central as c  # the HTTP client, process and wait helpers

ROOT = c.ROOT
SITES = ["site-1", "site-2", "site-3"]
GROUP = "gridscada"  # the group `demo --mqtt` publishes under


def site_plant(tmp, i):
    """A copy of the demo plant whose Modbus ports are moved by 1000*(i+1)."""
    dst = os.path.join(tmp, SITES[i], "plant")
    shutil.copytree(os.path.join(ROOT, "tags"), dst)
    for name in os.listdir(dst):
        path = os.path.join(dst, name)
        if not name.endswith(".toml"):
            continue
        text = open(path).read()
        text = re.sub(r"127\.0\.0\.1:(\d+)",
                      lambda m: f"127.0.0.1:{int(m.group(1)) + 1000 * (i + 1)}", text)
        open(path, "w").write(text)
    return os.path.join(dst, "gridscada.toml")


def login(base, data):
    return c.login(base, data, 90, 60)[0]


def start_edge(tmp, i, mport, hport):
    data = os.path.join(tmp, SITES[i], "data")
    return c.start([c.BIN, "demo", "--config", site_plant_paths[i], "--http", f"127.0.0.1:{hport}",
                    "--data", data, "--mqtt", f"mqtt://127.0.0.1:{mport}", "--mqtt-node", SITES[i]],
                   os.path.join(tmp, f"{SITES[i]}-{time.time():.0f}.log")), data


def browser_test(tmp, central_port, site, site_port):
    """Runs the remote panel's browser test (node --test, headless Chromium,
    as tests/e2e/browser.sh does); True if it passed."""
    browser = os.path.join(ROOT, "tests", "e2e", "browser")
    env = dict(os.environ)
    node_bin = os.path.join(ROOT, "target", "test-node", "node_modules", ".bin")
    if os.path.isdir(node_bin):  # browser.sh's Node.js 22, when Debian's is too old
        env["PATH"] = node_bin + os.pathsep + env["PATH"]
    if not os.path.isdir(os.path.join(browser, "node_modules", "playwright-core")):
        subprocess.run(["npm", "ci", "--no-audit", "--no-fund", "--loglevel=error"], cwd=browser, env=env)
    env.update({
        "GRIDSCADA_URL": f"http://127.0.0.1:{central_port}",
        "GRIDSCADA_CREDENTIALS": os.path.join(tmp, "central-data", "credentials.txt"),
        "GRIDSCADA_SITE": site,
        "GRIDSCADA_SITE_URL": f"http://127.0.0.1:{site_port}",
        "GRIDSCADA_SITE_CREDENTIALS": os.path.join(tmp, site, "data", "credentials.txt"),
        "GRIDSCADA_ARTIFACTS": os.path.join(tmp, "browser"),
    })
    log = os.path.join(tmp, "browser.log")
    with open(log, "w") as out:
        try:
            rc = subprocess.run(["node", "--test", "--test-reporter=spec", "sites/remote-panel.test.js"],
                                cwd=browser, env=env, stdout=out, stderr=subprocess.STDOUT, timeout=300).returncode
        except subprocess.TimeoutExpired:
            rc = -1
    if rc != 0:
        print(open(log).read()[-3000:])
    return rc == 0


site_plant_paths = []


def main(tmp):
    mport, central_port = c.free_port(), c.free_port()
    with open(os.path.join(tmp, "mosquitto.conf"), "w") as f:
        f.write(f"listener {mport} 127.0.0.1\nallow_anonymous true\npersistence false\n")
    broker = c.start([c.MOSQUITTO, "-c", os.path.join(tmp, "mosquitto.conf")],
                     os.path.join(tmp, "mosquitto.log"))
    time.sleep(0.5)

    conf = os.path.join(tmp, "central")
    os.makedirs(conf)
    with open(os.path.join(conf, "gridscada.toml"), "w") as f:
        f.write(f"""[mqtt]
broker = "mqtt://127.0.0.1:{mport}"
group = "{GROUP}"

[mqtt.host]
host_id = "central"
write_timeout_s = 15
""")
    central = c.start([c.BIN, "demo", "--config", conf, "--http", f"127.0.0.1:{central_port}",
                       "--data", os.path.join(tmp, "central-data")], os.path.join(tmp, "central.log"))
    api = login(f"http://127.0.0.1:{central_port}", os.path.join(tmp, "central-data"))
    if not c.check(api is not None, "the central host starts and an administrator logs in"):
        return

    edge_ports = [c.free_port() for _ in SITES]
    edges, edge_apis = [], []
    for i in range(len(SITES)):
        site_plant_paths.append(site_plant(tmp, i))
    for i in range(len(SITES)):
        edges.append(start_edge(tmp, i, mport, edge_ports[i])[0])
    for i in range(len(SITES)):
        edge_apis.append(login(f"http://127.0.0.1:{edge_ports[i]}", os.path.join(tmp, SITES[i], "data")))
    if not c.check(all(edge_apis), "three edge gridscada processes start (three simulated plants)"):
        return

    # Every tag of every site at the centre, once the edges have read them.
    def site_tags(tags, site):
        p = site + "."
        return {n[len(p):]: t for n, t in tags.items() if n.startswith(p)}

    def all_born():
        tags = api.tags()
        return all(len(site_tags(tags, s)) >= len(edge_apis[i].tags())
                   for i, s in enumerate(SITES)) and tags
    tags, secs = c.wait_for(all_born, 90, 0.5)
    c.check(tags, f"the central /api/tags holds every tag of the three sites ({secs:.1f} s)",
            {s: len(site_tags(api.tags(), s)) for s in SITES})
    if not tags:
        return

    # Qualities and discrete values agree with each edge's own /api/tags
    # (analog values move between the two reads; they are compared by the
    # edge test against an independent host).
    def agree(i):
        local, remote = edge_apis[i].tags(), site_tags(api.tags(), SITES[i])
        wrong = [n for n, t in local.items()
                 if n not in remote
                 or remote[n]["quality"]["code"] != t["quality"]["code"]
                 or (isinstance(t["value"], (bool, str)) and remote[n]["value"] != t["value"])]
        detail = [(n, (local[n]["quality"], local[n]["value"]),
                   (remote[n]["quality"], remote[n]["value"]) if n in remote else None)
                  for n in wrong[:5]]
        return (not wrong, detail)
    for i, s in enumerate(SITES):
        good, wrong = c.wait_for(lambda: agree(i)[0], 20, 0.5)[0], agree(i)[1]
        c.check(good, f"{s}: qualities and discrete values at the centre equal the edge's", wrong)

    # A browser on the central server: one remote site's panel, drawn from
    # its remote tags, live and following the edge's quality
    # (tests/e2e/browser/sites/remote-panel.test.js).
    c.check(browser_test(tmp, central_port, SITES[0], edge_ports[0]),
            f"a browser on the central server shows {SITES[0]}'s panel live, Bad and Good again with the edge")

    # The edge's alarms, raised at the centre on the remote tags: a fault
    # on site-1's first panel trips it; every tag alarm standing at the
    # edge stands at the centre as site-1.KEY (the alarm definitions come
    # with the births), in the site's area.
    alarm_site = 0
    everything = "?state=normal,unack_active,ack_active,unack_rtn,shelved,suppressed,out_of_service"
    panel = edge_apis[alarm_site].call("GET", "/api/panels")[1]
    panel = (panel.get("panels", panel) if isinstance(panel, dict) else panel)[0]
    panel = panel.get("id") or panel.get("name")
    status, body = edge_apis[alarm_site].call("POST", "/api/sim/faults",
                                              {"panel": panel, "zone": 1, "kind": "permanent"})
    c.check(status in (200, 201, 204), f"a permanent fault on {SITES[alarm_site]}'s panel {panel}", (status, body))
    tag_kinds = ("hihi", "hi", "lo", "lolo", "discrete")

    def alarms_agree():
        edge = [a for a in edge_apis[alarm_site].call("GET", "/api/alarms" + everything)[1]["alarms"]
                if a["kind"] in tag_kinds and a["active"]]
        centre = {a["key"]: a for a in api.call("GET", "/api/alarms" + everything)[1]["alarms"]
                  if a["key"].startswith(SITES[alarm_site] + ".") and a["active"]}
        missing = [a["key"] for a in edge if f"{SITES[alarm_site]}.{a['key']}" not in centre]
        in_area = all(a["tag"].startswith(SITES[alarm_site] + ".")
                      and a["selection"].startswith(SITES[alarm_site] + ".") for a in centre.values())
        return (not missing and in_area and [a["key"] for a in edge],
                ([a["key"] for a in edge], missing, list(centre)[:5]))
    ok, secs = c.wait_for(lambda: alarms_agree()[0], 30, 0.5)
    c.check(ok, f"the edge's {len(ok or [])} standing tag alarms stand at the centre on the remote tags "
            f"({secs:.1f} s)", alarms_agree()[1])
    edge_apis[alarm_site].call("DELETE", f"/api/sim/faults/{panel}/1")

    # A broker outage: the edges keep what changed meanwhile and send it as
    # historical data afterwards; the centre's historian takes it at its own
    # timestamps (the live value of the window is only the Bad of the lost
    # broker).
    counter = next(n for n in sorted(edge_apis[0].tags()) if n.endswith(".Comm.Requests"))
    broker.terminate()
    broker.wait()
    down_from = int(time.time() * 1000)
    time.sleep(8)
    down_to = int(time.time() * 1000)
    broker = c.start([c.MOSQUITTO, "-c", os.path.join(tmp, "mosquitto.conf")],
                     os.path.join(tmp, "mosquitto-2.log"))
    tag = f"{SITES[0]}.{counter}"

    def history_in_outage():
        status, body = api.call(
            "GET", f"/api/trends?tags={tag}&from={down_from + 1000}&to={down_to - 1000}&points=20")
        if status != 200:
            return None
        buckets = body["series"][0]["buckets"]
        return [b for b in buckets if b.get("avg") is not None] or None
    got, secs = c.wait_for(history_in_outage, 60, 1)
    c.check(got and len(got) >= 3,
            f"{sum(b['count'] for b in got or [])} samples of {tag} from the broker outage reach the central "
            f"historian at their own times ({secs:.1f} s)",
            got)
    c.check(c.wait_for(lambda: all(agree(i)[0] for i in range(len(SITES))), 60, 0.5)[0],
            "after the outage every site's tags at the centre equal the edge's again")

    # kill -9 one edge: its tags turn Bad at the centre, only its.
    victim = 1
    edges[victim].send_signal(signal.SIGKILL)
    edges[victim].wait()
    t0 = time.monotonic()

    def dead():
        tags = api.tags()
        return all(t["quality"]["code"] == "bad" for t in site_tags(tags, SITES[victim]).values())
    went, secs = c.wait_for(dead, 20, 0.2)
    c.check(went, f"kill -9 of {SITES[victim]}: all its tags Bad at the centre after {time.monotonic() - t0:.1f} s (keep-alive 10 s)")
    others_good = sum(t["quality"]["code"] == "good"
                      for s in (SITES[0], SITES[2]) for t in site_tags(api.tags(), s).values())
    c.check(others_good > 0 and all(agree(i)[0] for i in (0, 2)),
            "the other two sites stay as their edges report them", others_good)

    # Restart it: a rebirth brings its tags back.
    edges[victim], _ = start_edge(tmp, victim, mport, edge_ports[victim])
    edge_apis[victim] = login(f"http://127.0.0.1:{edge_ports[victim]}",
                              os.path.join(tmp, SITES[victim], "data"))
    back, secs = c.wait_for(lambda: agree(victim)[0], 90, 0.5)
    c.check(back, f"restarting {SITES[victim]} brings its tags back through a rebirth ({secs:.1f} s)",
            agree(victim)[1])

    # A write from the centre reaches the right site's device.
    target_site, other_site = 2, 0
    name = next((n for n, t in sorted(edge_apis[target_site].tags().items())
                 if t.get("writable") and isinstance(t["value"], bool) and n.endswith(".Cmd")), None)
    if not c.check(name is not None, "the demo plant has a writable breaker command", name):
        return
    old = edge_apis[target_site].tags()[name]["value"]
    other_before = edge_apis[other_site].tags()[name]["value"]
    t0 = time.monotonic()
    status, body = api.call("POST", f"/api/tags/{SITES[target_site]}.{name}/write", {"value": not old})
    took = time.monotonic() - t0
    c.check(status == 200, f"a write from the centre to {SITES[target_site]}.{name} is confirmed ({took:.1f} s)",
            (status, body))
    c.check(edge_apis[target_site].tags()[name]["value"] == (not old),
            f"{SITES[target_site]}'s own device reads {name} = {not old}")
    c.check(edge_apis[other_site].tags()[name]["value"] == other_before,
            f"{SITES[other_site]}'s {name} is untouched")
    status, events = edge_apis[target_site].call("GET", "/api/events?limit=200")
    text = str(events)
    c.check(f"requests {name}" in text and f"wrote {name}" in text,
            "the edge's event log has the DCMD write (request and confirmation)", text[:300])
    status, events = api.call("GET", "/api/events?limit=200")
    c.check(f"wrote {SITES[target_site]}.{name}" in str(events),
            "the central event log has the operator's write")
    api.call("POST", f"/api/tags/{SITES[target_site]}.{name}/write", {"value": old})

    central.send_signal(signal.SIGTERM)


if __name__ == "__main__":
    tmp = tempfile.mkdtemp(prefix="gridscada-sites-")
    try:
        main(tmp)
    except Exception as e:
        import traceback
        traceback.print_exc()
        c.bad(f"the test stopped: {e}")
    finally:
        for p in c.procs:
            if p.poll() is None:
                p.terminate()
                try:
                    p.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    p.kill()
        if c.failed:
            print(f"logs kept in {tmp}")
            for name in sorted(os.listdir(tmp)):
                if name.endswith(".log"):
                    print(f"--- {name} (last 15 lines)")
                    print("".join(open(os.path.join(tmp, name)).readlines()[-15:]))
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    print(f"{c.passed} passed, {c.failed} failed")
    sys.exit(1 if c.failed else 0)
