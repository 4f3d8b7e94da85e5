"""OPC UA interoperability: Python asyncua (FreeOpcUa) as the client of a
running `gridscada demo --opcua PORT`, checked against the HTTP API.

Usage: opcua_client.py PHASE BASE_URL OPC_URL CREDENTIALS TMPDIR

PHASE "plant" (the embedded demo plant, with its 11 kV ring): browse the address space (folders
follow the dotted names, one variable per tag), read every tag and compare
value and status with /api/tags, subscribe and receive changes within a
scan, a user whose role may not write a tag is refused (and audited), a
switching device with a "Do not close" safety tag refuses a close (in the
tag's words, audited), a wrong password is refused (and audited), anonymous sessions are refused,
Basic256Sha256 Sign and SignAndEncrypt work, and /metrics counts it all.

PHASE "write" (tests/plants/three-panels, no dispatch loop writing
setpoints): a setpoint written over OPC UA is confirmed by the device
(/api/tags, the event log), an out-of-limits write is refused and on
record as refused, a user without write rights (a guest made through the
API) and an operator whose group's screens do not show the tag are refused.

Prints "ok ..." / "FAIL ..." lines, then "N passed, M failed".
"""

import asyncio
import json
import math
import sys
import time
import urllib.error
import urllib.request

from asyncua import Client, ua
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

NS_URI = "urn:gridscada:tags"
passed = 0
failed = 0


def check(name, cond, detail=""):
    global passed, failed
    if cond:
        passed += 1
        print(f"ok   {name}")
    else:
        failed += 1
        print(f"FAIL {name}: {detail}")
    return cond


class Api:
    """The HTTP API, logged in with a session cookie."""

    def __init__(self, base):
        self.base = base
        self.cookie = None

    def call(self, method, path, body=None):
        data = json.dumps(body).encode() if body is not None else None
        req = urllib.request.Request(self.base + path, data=data, method=method)
        if data is not None:
            req.add_header("Content-Type", "application/json")
        req.add_header("Origin", self.base)
        if self.cookie:
            req.add_header("Cookie", self.cookie)
        try:
            with urllib.request.urlopen(req, timeout=30) as r:
                status, headers, text = r.status, r.headers, r.read().decode()
        except urllib.error.HTTPError as e:
            status, headers, text = e.code, e.headers, e.read().decode()
        return status, headers, (json.loads(text) if text.strip() else None)

    def login(self, user, password):
        status, headers, _ = self.call(
            "POST", "/api/session", {"username": user, "password": password}
        )
        if status != 200:
            raise RuntimeError(f"login as {user}: HTTP {status}")
        self.cookie = headers["Set-Cookie"].split(";")[0]

    def tags(self):
        status, _, body = self.call("GET", "/api/tags")
        if status != 200:
            raise RuntimeError(f"/api/tags: HTTP {status}")
        return {t["name"]: t for t in body["tags"]}

    def events(self, text):
        status, _, body = self.call(
            "GET", "/api/events?limit=50&text=" + urllib.request.quote(text)
        )
        return body["events"] if status == 200 else []


def credentials(path):
    out = {}
    for line in open(path):
        parts = line.split()
        if len(parts) >= 3 and parts[0] in ("administrator", "supervisor", "operator"):
            out[parts[0]] = (parts[1], parts[2])
    return out


def client(url, user=None, password=None, timeout=10):
    c = Client(url, timeout=timeout)
    if user is not None:
        c.set_user(user)
        c.set_password(password)
    return c


async def secure_client(url, tmp, mode, user, password):
    """A client with its own self-signed certificate (the demo trusts client
    certificates on first sight)."""
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID

    from pathlib import Path

    key, cert = Path(tmp) / "client-key.pem", Path(tmp) / "client-cert.der"
    uri = "urn:gridscada-tests:asyncua"
    await setup_self_signed_certificate(
        key, cert, uri, "localhost", [ExtendedKeyUsageOID.CLIENT_AUTH],
        {"countryName": "EU", "organizationName": "gridscada tests", "commonName": "asyncua"},
    )
    c = client(url, user, password)
    c.application_uri = uri
    await c.set_security(SecurityPolicyBasic256Sha256, cert, key, mode=mode)
    return c


async def browse_tags(c):
    """Every variable under Objects/Tags, by its dotted path of browse names,
    with its node; and the folders, by path."""
    ns = await c.get_namespace_index(NS_URI)
    root = c.get_node(ua.NodeId(0, ns))
    variables, folders = {}, {}

    async def walk(node, path):
        for child in await node.get_children(refs=ua.ObjectIds.Organizes):
            name = (await child.read_browse_name()).Name
            full = f"{path}.{name}" if path else name
            cls = await child.read_node_class()
            if cls == ua.NodeClass.Variable:
                variables[full] = child
            elif cls == ua.NodeClass.Object:
                folders[full] = child
                await walk(child, full)

    await walk(root, "")
    return ns, variables, folders


def status_class(code):
    s = ua.StatusCode(code)
    return "good" if s.is_good() else "uncertain" if s.is_uncertain() else "bad"


def same_value(api_value, opc_value):
    if isinstance(api_value, bool) or isinstance(opc_value, bool):
        return api_value == opc_value
    if isinstance(api_value, str) and not isinstance(opc_value, str):
        try:
            return int(api_value) == opc_value
        except ValueError:
            return False
    if isinstance(api_value, (int, float)) and isinstance(opc_value, (int, float)):
        if isinstance(api_value, float) and math.isnan(api_value):
            return math.isnan(opc_value)
        # An f32 register is exact in both (the Float variant narrows nothing).
        return api_value == opc_value or math.isclose(api_value, opc_value, rel_tol=1e-6)
    return api_value == opc_value


def ms(dt):
    return None if dt is None else round(dt.timestamp() * 1000)


async def read_all(c, nodes):
    """DataValues of `nodes` in one Read per thousand."""
    out = []
    for i in range(0, len(nodes), 1000):
        chunk = nodes[i : i + 1000]
        params = ua.ReadParameters()
        params.TimestampsToReturn = ua.TimestampsToReturn.Both
        for n in chunk:
            rv = ua.ReadValueId()
            rv.NodeId = n.nodeid
            rv.AttributeId = ua.AttributeIds.Value
            params.NodesToRead.append(rv)
        out.extend(await c.uaclient.read(params))
    return out


async def phase_plant(base, url, creds, tmp):
    api = Api(base)
    admin, operator = creds["administrator"], creds["operator"]
    api.login(*admin)
    tags = api.tags()
    check("/api/tags lists the demo's tags", len(tags) > 50, len(tags))

    async with client(url, *admin) as c:
        ns, variables, folders = await browse_tags(c)
        check(
            "browse: one variable per tag, on the path of its dotted name",
            set(variables) == set(tags),
            f"only in OPC UA {sorted(set(variables) - set(tags))[:5]}, "
            f"only in the API {sorted(set(tags) - set(variables))[:5]}",
        )
        ids_ok = all(n.nodeid == ua.NodeId(name, ns) for name, n in variables.items())
        check("each tag's node id is ns=<tags>;s=<tag name>", ids_ok)
        prefixes = {name.rsplit(".", 1)[0] for name in tags if "." in name}
        parents = set()
        for p in prefixes:
            parts = p.split(".")
            parents.update(".".join(parts[: i + 1]) for i in range(len(parts)))
        check(
            "browse: a folder for every name prefix",
            parents <= set(folders),
            sorted(parents - set(folders))[:5],
        )

        # Data types and access levels of a few kinds of tag.
        want_types = {"bool": ua.VariantType.Boolean, "str": ua.VariantType.String}
        wrong = []
        for name, t in tags.items():
            if t["kind"] in want_types and name in variables:
                dt = await variables[name].read_data_type_as_variant_type()
                if dt != want_types[t["kind"]]:
                    wrong.append((name, dt))
        check("data types: booleans are Boolean, text is String", not wrong, wrong[:5])
        floats = [n for n, t in tags.items() if t["kind"] == "float"]
        dts = {await variables[n].read_data_type_as_variant_type() for n in floats[:20]}
        check(
            "data types: engineering floats are Float or Double",
            dts <= {ua.VariantType.Float, ua.VariantType.Double} and dts,
            dts,
        )
        with_units = [n for n, t in tags.items() if t.get("units")]
        if with_units:
            n = variables[with_units[0]]
            props = await n.get_properties()
            eu = None
            for p in props:
                if (await p.read_browse_name()).Name == "EngineeringUnits":
                    eu = await p.read_value()
            check(
                f"{with_units[0]} carries EngineeringUnits '{tags[with_units[0]]['units']}'",
                eu is not None and eu.DisplayName.Text == tags[with_units[0]]["units"],
                eu,
            )
        writable = [n for n, t in tags.items() if t["writable"]]
        readonly = [n for n, t in tags.items() if not t["writable"]]
        lv = await variables[writable[0]].read_attribute(ua.AttributeIds.AccessLevel)
        ro = await variables[readonly[0]].read_attribute(ua.AttributeIds.AccessLevel)
        check(
            "access level: writable tags CurrentWrite, others read-only",
            lv.Value.Value & 2 and not ro.Value.Value & 2 and ro.Value.Value & 1,
            (lv.Value.Value, ro.Value.Value),
        )

        # Every tag: value and status as /api/tags has them. A tag matches
        # when both show the same reading (the same source timestamp); one
        # read between two scans is read again.
        names = sorted(tags)
        pending = set(names)
        mismatched = {}
        for _ in range(6):
            todo = sorted(pending)
            dvs = await read_all(c, [variables[n] for n in todo])
            now_api = api.tags()
            for n, dv in zip(todo, dvs):
                t = now_api[n]
                src = ms(dv.SourceTimestamp)
                if t["timestamp"] == 0:
                    # Never read: no value, Bad waiting for initial data.
                    if dv.StatusCode.value == ua.StatusCodes.BadWaitingForInitialData:
                        pending.discard(n)
                    continue
                if src != t["timestamp"]:
                    continue  # another scan: read again
                value = dv.Value.Value if dv.Value is not None else None
                cls = status_class(dv.StatusCode.value)
                if cls == t["quality"]["code"] and same_value(t["value"], value):
                    pending.discard(n)
                    mismatched.pop(n, None)
                else:
                    mismatched[n] = (t["value"], t["quality"], value, str(dv.StatusCode))
            if not pending:
                break
            await asyncio.sleep(0.3)
        check(
            f"read: all {len(names)} tags carry the value, status class and source timestamp of /api/tags",
            not pending,
            f"{len(pending)} differ, e.g. {[(n, mismatched.get(n)) for n in sorted(pending)[:5]]}",
        )
        dvs = await read_all(c, [variables[n] for n in names])
        codes = {}
        for n, dv in zip(names, dvs):
            codes.setdefault(status_class(dv.StatusCode.value), []).append(n)
        print(f"     status classes now: { {k: len(v) for k, v in codes.items()} }")
        check(
            "read: server timestamps are set and recent",
            all(dv.ServerTimestamp and abs(time.time() - dv.ServerTimestamp.timestamp()) < 60 for dv in dvs),
        )

        # Subscription: every tag monitored; changes arrive within a scan.
        class Handler:
            def __init__(self):
                self.changes = []

            def datachange_notification(self, node, val, data):
                dv = data.monitored_item.Value
                self.changes.append((time.time(), node.nodeid.Identifier, dv))

        handler = Handler()
        sub = await c.create_subscription(100, handler)
        await sub.subscribe_data_change([variables[n] for n in names], queuesize=1)
        await asyncio.sleep(1.0)
        initial = len(handler.changes)
        check(
            "subscribe: an initial value for every monitored tag",
            initial >= len(names),
            f"{initial} of {len(names)}",
        )
        start = time.time()
        await asyncio.sleep(4.0)
        later = [x for x in handler.changes if x[0] >= start]
        delays = sorted(
            x[0] - x[2].SourceTimestamp.timestamp() for x in later if x[2].SourceTimestamp
        )
        changed = {x[1] for x in later}
        check(
            "subscribe: changes keep arriving (values that move between scans)",
            len(changed) >= 3,
            f"{len(later)} changes of {len(changed)} tags in 4 s",
        )
        if delays:
            p50 = delays[len(delays) // 2]
            worst = delays[-1]
            print(f"     {len(later)} changes in 4 s; delay from source timestamp p50 {p50*1000:.0f} ms, max {worst*1000:.0f} ms")
            # Pushed at the next scan, not held: the median within a scan
            # (1 s), and none stalled. The worst case is not a scan: on CI
            # the replay shares the two cores with this stage (figures
            # belong to the benchmarks).
            check("subscribe: changes arrive within a scan (1 s) of their reading, none stalled",
                  p50 < 1.5 and worst < 5.0, f"p50 {p50:.2f} s, max {worst:.2f} s")
        # A change seen over OPC UA is the value /api/tags shows.
        if later:
            _, name, dv = later[-1]
            await asyncio.sleep(0.2)
            t = api.tags()[name]
            check(
                f"subscribe: the last change of {name} is a reading /api/tags has had",
                ms(dv.SourceTimestamp) <= t["timestamp"],
                (ms(dv.SourceTimestamp), t["timestamp"]),
            )
        await sub.delete()

    # The operator may not write a supervisor's setpoint.
    sp = next(
        (n for n, t in tags.items() if t["writable"] and t.get("write_role") in ("supervisor", "administrator")),
        None,
    )
    if check("the demo has a tag above the operator's rights", sp is not None):
        async with client(url, *operator) as c:
            ns = await c.get_namespace_index(NS_URI)
            node = c.get_node(ua.NodeId(sp, ns))
            ual = await node.read_attribute(ua.AttributeIds.UserAccessLevel)
            check(f"operator's UserAccessLevel of {sp} has no CurrentWrite", not ual.Value.Value & 2, ual.Value.Value)
            before = (await node.read_data_value()).Value
            try:
                await node.write_value(ua.DataValue(ua.Variant(12.0, before.VariantType)))
                check(f"operator writing {sp} is refused", False, "the write returned Good")
            except ua.UaStatusCodeError as e:
                check(
                    f"operator writing {sp} is refused (BadUserAccessDenied)",
                    e.code == ua.StatusCodes.BadUserAccessDenied,
                    str(e),
                )
        ev = [e for e in api.events(sp) if e["kind"] == "write_refused" and "OPC UA" in e["message"]]
        check("the refused write is in the event log", ev and ev[0]["user"] == operator[0], ev[:1])

    await safety_tag_refuses_write(api, url, operator, tags)

    # A wrong password, and no anonymous sessions.
    try:
        async with client(url, admin[0], admin[1] + "x"):
            pass
        check("a wrong password is refused (BadUserAccessDenied)", False, "the session opened")
    except Exception as e:  # asyncua raises the service fault's status
        check("a wrong password is refused (BadUserAccessDenied)", "BadUserAccessDenied" in repr(e), repr(e))
    ev = [e for e in api.events(admin[0]) if e["kind"] == "login_failed" and e["source"] == "opcua"]
    check("the failed login is in the event log (source opcua)", bool(ev), api.events(admin[0])[:2])
    try:
        async with client(url):
            pass
        check("anonymous sessions are refused (off unless configured)", False, "the session opened")
    except Exception as e:
        check("anonymous sessions are refused (off unless configured)", True, repr(e))

    # Basic256Sha256: Sign, and SignAndEncrypt.
    some = sorted(tags)[0]
    for mode in (ua.MessageSecurityMode.Sign, ua.MessageSecurityMode.SignAndEncrypt):
        try:
            c = await secure_client(url, tmp, mode, *admin)
            async with c:
                ns = await c.get_namespace_index(NS_URI)
                dv = await c.get_node(ua.NodeId(some, ns)).read_data_value()
                check(f"Basic256Sha256 {mode.name}: a session reads {some}", dv.StatusCode is not None)
        except Exception as e:
            check(f"Basic256Sha256 {mode.name}: a session reads {some}", False, repr(e))

    text = urllib.request.urlopen(base + "/metrics", timeout=10).read().decode()
    figures = {}
    for line in text.splitlines():
        if line.startswith("gridscada_opcua_"):
            k, v = line.rsplit(" ", 1)
            figures[k] = float(v)
    check(
        "/metrics: OPC UA reads, refused writes, refused logins and sessions",
        figures.get("gridscada_opcua_reads_total", 0) >= len(tags)
        and figures.get("gridscada_opcua_writes_refused_total", 0) >= 1
        and figures.get("gridscada_opcua_logins_refused_total", 0) >= 1
        and figures.get("gridscada_opcua_sessions_opened_total", 0) >= 3
        and "gridscada_opcua_subscriptions" in figures
        and figures.get("gridscada_opcua_notifications_total", 0) >= 1,
        figures,
    )


async def phase_write(base, url, creds, tmp):
    api = Api(base)
    admin, operator = creds["administrator"], creds["operator"]
    api.login(*admin)
    tags = api.tags()
    sp = next(
        (n for n, t in tags.items() if t["writable"] and t["kind"] == "float" and t.get("write_role") == "operator"),
        None,
    )
    if not check("the plant has a float setpoint operators may write", sp is not None):
        return
    # A guest: may log in and read, may write nothing.
    status, _, body = api.call(
        "POST", "/api/users", {"name": "opcua-guest", "role": "guest", "password": "guest-password-1"}
    )
    check("a guest user is made through the API", status in (200, 201), (status, body))

    current = tags[sp]["value"]
    new = 17.5 if abs(current - 17.5) > 1 else 23.5
    async with client(url, *operator) as c:
        ns = await c.get_namespace_index(NS_URI)
        node = c.get_node(ua.NodeId(sp, ns))
        t0 = time.time()
        try:
            await node.write_value(ua.DataValue(ua.Variant(new, ua.VariantType.Float)))
            took = time.time() - t0
            check(f"operator writes {sp} = {new}: Good once the device confirmed ({took*1000:.0f} ms)", True)
        except ua.UaStatusCodeError as e:
            check(f"operator writes {sp} = {new}", False, str(e))
        t = api.tags()[sp]
        check(
            f"/api/tags shows {sp} = {new}, Good, right after the write returned",
            t["value"] == new and t["quality"]["code"] == "good",
            (t["value"], t["quality"]),
        )
        dv = await node.read_data_value()
        check(f"OPC UA reads back {sp} = {new}", dv.Value.Value == new and dv.StatusCode.is_good(), dv)
        # A value out of the tag's engineering limits is refused, not written.
        try:
            await node.write_value(ua.DataValue(ua.Variant(1e6, ua.VariantType.Float)))
            check(f"{sp} = 1e6 (beyond its limits) is refused", False, "Good")
        except ua.UaStatusCodeError as e:
            check(f"{sp} = 1e6 (beyond its limits) is refused (BadOutOfRange)", e.code == ua.StatusCodes.BadOutOfRange, str(e))
        check(f"{sp} still {new} after the refused write", api.tags()[sp]["value"] == new)
    events = api.events(sp)
    # Refused by the server before the device, so on record as refused
    # (issue 36 #11), not as a failed write.
    check(
        "the out-of-limits write is on record as write_refused via OPC UA, not write_failed",
        any(e["kind"] == "write_refused" and "via OPC UA" in e["message"] and "engineering limits" in e["message"] for e in events)
        and not any(e["kind"] == "write_failed" for e in events),
        [(e["kind"], e["message"]) for e in events[:4]],
    )
    kinds = [(e["kind"], e["user"]) for e in events]
    check(
        "the event log has the request and the confirmed write, by the operator, via OPC UA",
        ("write_request", operator[0]) in kinds
        and any(e["kind"] == "write" and "via OPC UA" in e["message"] and f"confirmed {new}" in e["message"] for e in events),
        events[:3],
    )

    # The guest reads what the HMI shows a guest (the screens of its group),
    # nothing else.
    guest_api = Api(base)
    guest_api.login("opcua-guest", "guest-password-1")
    guest_tags = guest_api.tags()
    visible = sorted(guest_tags)[0] if guest_tags else None
    check("the guest may read some tags in the HMI, not the setpoint", visible and sp not in guest_tags, (len(guest_tags), sp))
    async with client(url, "opcua-guest", "guest-password-1") as c:
        ns = await c.get_namespace_index(NS_URI)
        dv = await c.get_node(ua.NodeId(visible, ns)).read_data_value()
        check(f"the guest reads {visible} over OPC UA, as in the HMI", dv.StatusCode.is_good() or dv.StatusCode.is_bad() and dv.StatusCode.value != ua.StatusCodes.BadUserAccessDenied, dv)
        node = c.get_node(ua.NodeId(sp, ns))
        try:
            dv = await node.read_data_value()
            check(f"the guest may not read {sp} (not on its screens)", False, dv)
        except ua.UaStatusCodeError as e:
            check(f"the guest may not read {sp} (not on its screens): BadUserAccessDenied", e.code == ua.StatusCodes.BadUserAccessDenied, str(e))
        try:
            await node.write_value(ua.DataValue(ua.Variant(new + 1, ua.VariantType.Float)))
            check("a user without write rights is refused", False, "Good")
        except ua.UaStatusCodeError as e:
            check("a user without write rights (guest) is refused (BadUserAccessDenied)", e.code == ua.StatusCodes.BadUserAccessDenied, str(e))
    check(f"{sp} unchanged by the guest", api.tags()[sp]["value"] == new)
    ev = [e for e in api.events(sp) if e["kind"] == "write_refused" and e["user"] == "opcua-guest"]
    check("the guest's refused write is in the event log", bool(ev), api.events(sp)[:3])

    # Write access follows the areas of read access (issue 36 #5): an
    # operator whose group's screens do not show the setpoint may not write
    # it over OPC UA either.
    status, _, body = api.call(
        "POST", "/api/users", {"name": "opcua-west", "role": "operator", "group": "west", "password": "west-password-1"}
    )
    check("an operator of group west is made through the API", status in (200, 201), (status, body))
    status, _, body = api.call("PUT", "/api/groups/west/screens", {"screens": ["alarms"]})
    check("group west may open the alarms only", status == 200, (status, body))
    async with client(url, "opcua-west", "west-password-1") as c:
        ns = await c.get_namespace_index(NS_URI)
        try:
            await c.get_node(ua.NodeId(sp, ns)).write_value(ua.DataValue(ua.Variant(new + 2, ua.VariantType.Float)))
            check(f"an operator outside the area of {sp} is refused", False, "Good")
        except ua.UaStatusCodeError as e:
            check(f"an operator outside the area of {sp} is refused (BadUserAccessDenied)", e.code == ua.StatusCodes.BadUserAccessDenied, str(e))
    check(f"{sp} unchanged by the operator outside its area", api.tags()[sp]["value"] == new)
    ev = [e for e in api.events(sp) if e["kind"] == "write_refused" and e["user"] == "opcua-west"]
    check("the refusal is on record with its reason (the area)", ev and "area" in ev[0]["message"], api.events(sp)[:3])

    # A read-only tag cannot be written by anyone.
    ro = next(n for n, t in tags.items() if not t["writable"] and t["kind"] == "float")
    async with client(url, *admin) as c:
        ns = await c.get_namespace_index(NS_URI)
        try:
            await c.get_node(ua.NodeId(ro, ns)).write_value(ua.DataValue(ua.Variant(1.0, ua.VariantType.Double)))
            check(f"writing read-only {ro} is refused", False, "Good")
        except ua.UaStatusCodeError as e:
            check(f"writing read-only {ro} is refused (BadNotWritable)", e.code == ua.StatusCodes.BadNotWritable, str(e))


async def safety_tag_refuses_write(api, url, operator, tags):
    """A "Do not close" safety tag on a switching device refuses an OPC UA
    write that would close it (BadRequestNotAllowed), in the tag's words in
    the event log, like every other command path (docs/NETWORK.md)."""
    st, _, model = api.call("GET", "/api/network")
    if not check("the demo has a switching network (/api/network)", st == 200, st):
        return
    switch = next((w for w in model["switches"]
                   if w.get("command_tag") and tags.get(w["command_tag"], {}).get("write_role") == "operator"), None)
    if not check("a switching device an operator may command", switch is not None, model["switches"][:2]):
        return
    cmd = switch["command_tag"]
    st, _, placed = api.call("POST", "/api/switching/tags", {
        "device": switch["id"], "kind": "do_not_close",
        "reason": "OPC UA test: out for work", "work_ref": "WO-UA"})
    if not check(f"a do_not_close tag is placed on {switch['id']}", st in (200, 201), (st, placed)):
        return
    before = api.tags()[cmd]["value"]
    async with client(url, *operator) as c:
        ns = await c.get_namespace_index(NS_URI)
        try:
            await c.get_node(ua.NodeId(cmd, ns)).write_value(ua.DataValue(ua.Variant(True, ua.VariantType.Boolean)))
            check(f"closing {switch['id']} through OPC UA is refused by its safety tag", False, "the write returned Good")
        except ua.UaStatusCodeError as e:
            check(f"closing {switch['id']} through OPC UA is refused by its safety tag (BadRequestNotAllowed)",
                  e.code == ua.StatusCodes.BadRequestNotAllowed, str(e))
    ev = [e for e in api.events(cmd) if e["kind"] == "write_refused" and "DO NOT CLOSE" in e["message"]]
    check("the refusal is in the event log, naming the safety tag", bool(ev) and "OPC UA test: out for work" in ev[0]["message"],
          api.events(cmd)[:2])
    check(f"{cmd} unchanged", api.tags()[cmd]["value"] == before, api.tags()[cmd])
    st, _, _ = api.call("DELETE", f"/api/switching/tags/{placed['id']}", {"reason": "OPC UA test done"})
    check("the safety tag is removed", st == 200, st)


def main():
    phase, base, url, creds_path, tmp = sys.argv[1:6]
    creds = credentials(creds_path)
    fn = phase_plant if phase == "plant" else phase_write
    try:
        asyncio.run(fn(base, url, creds, tmp))
    except Exception as e:  # a crash is a failure, with its cause
        import traceback

        traceback.print_exc()
        check(f"phase {phase} ran to the end", False, repr(e))
    print(f"{passed} passed, {failed} failed")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
