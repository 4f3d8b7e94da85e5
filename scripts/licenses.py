#!/usr/bin/env python3
"""The licences of the crates gridscada is built from.

    python3 scripts/licenses.py check      # refuse a licence we cannot ship; the list must be current
    python3 scripts/licenses.py write      # regenerate THIRD-PARTY-LICENSES.md
    python3 scripts/licenses.py self-test  # the policy and the tree walk on made-up crates

The product's dependency tree is every crate reached from the workspace's
members through normal and build dependencies (`cargo metadata`, all
targets, so a Windows-only crate counts too); dev-dependencies and the
Python and npm test peers are not shipped and are not looked at.

A crate passes when its SPDX expression can be satisfied with the
permissive licences in ALLOWED (`A OR B` needs one of them, `A AND B` both).
Anything else is refused: the GPL family (GPL, AGPL, LGPL when it is the
only choice), non-commercial and other licences nobody has looked at yet,
and a crate that names no licence. A licence is added to ALLOWED only after
reading it. Needs only python3 and cargo (no cargo-deny or cargo-about to
build on CI's two cores).
"""
import json
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LIST = os.path.join(ROOT, "THIRD-PARTY-LICENSES.md")

# Permissive licences, and Apache-2.0 compatible: they allow use, change and
# sale, and ask for the notice to be kept (THIRD-PARTY-LICENSES.md does).
ALLOWED = {
    "0BSD", "Apache-2.0", "Apache-2.0 WITH LLVM-exception", "BSD-2-Clause",
    "BSD-3-Clause", "BSL-1.0", "CC0-1.0", "CDLA-Permissive-2.0", "ISC", "MIT",
    "MIT-0", "Unicode-3.0", "Unicode-DFS-2016", "Unlicense", "Zlib",
    # File-level copyleft: changes to its own files stay open, the rest of
    # the product does not (the MPL's own FAQ); compatible with Apache-2.0.
    "MPL-2.0",
}

# Why a licence is refused, for the message (anything not ALLOWED is).
REASONS = [
    (re.compile(r"^(A|L)?GPL"), "copyleft (GPL family)"),
    (re.compile(r"(^|-)NC(-|$)|NonCommercial|Non-Commercial", re.I), "non-commercial"),
]


def why_refused(licence):
    for pattern, reason in REASONS:
        if pattern.search(licence):
            return reason
    return "not in the allowed list of scripts/licenses.py"


def tokens(expr):
    # Old crates write `MIT/Apache-2.0` for `MIT OR Apache-2.0`.
    expr = expr.replace("/", " OR ")
    return re.findall(r"\(|\)|[^\s()]+", expr)


def acceptable(expr):
    """(True, []) when the SPDX expression can be met with ALLOWED licences;
    otherwise (False, the licences that stand in the way)."""
    toks = tokens(expr)
    pos = 0

    def peek():
        return toks[pos] if pos < len(toks) else None

    def take():
        nonlocal pos
        pos += 1
        return toks[pos - 1]

    # Each returns (ok, refused licences).
    def or_expr():
        ok, bad = and_expr()
        while peek() == "OR":
            take()
            ok2, bad2 = and_expr()
            ok, bad = (ok or ok2), ([] if ok or ok2 else bad + bad2)
        return ok, bad

    def and_expr():
        ok, bad = term()
        while peek() == "AND":
            take()
            ok2, bad2 = term()
            ok, bad = ok and ok2, bad + bad2
        return ok, bad

    def term():
        t = peek()
        if t is None or t in ("AND", "OR", "WITH", ")"):
            raise ValueError(f"malformed licence expression: {expr!r}")
        take()
        if t == "(":
            r = or_expr()
            if peek() != ")":
                raise ValueError(f"malformed licence expression: {expr!r}")
            take()
            return r
        name = t.rstrip("+")  # `GPL-2.0+`: the GPL still
        if peek() == "WITH":
            take()
            name = f"{name} WITH {take()}"
        return (True, []) if name in ALLOWED else (False, [name])

    ok, bad = or_expr()
    if pos != len(toks):
        raise ValueError(f"malformed licence expression: {expr!r}")
    return ok, bad


def product_crates(meta):
    """Third-party packages reached from the workspace through normal and
    build dependencies, sorted by name and version."""
    packages = {p["id"]: p for p in meta["packages"]}
    nodes = {n["id"]: n for n in meta["resolve"]["nodes"]}
    members = set(meta["workspace_members"])
    seen, todo = set(), list(members)
    while todo:
        pid = todo.pop()
        if pid in seen:
            continue
        seen.add(pid)
        for dep in nodes[pid]["deps"]:
            kinds = {k["kind"] for k in dep.get("dep_kinds", [{"kind": None}])}
            if kinds & {None, "build"}:
                todo.append(dep["pkg"])
    crates = [packages[p] for p in seen - members]
    return sorted(crates, key=lambda p: (p["name"], version_key(p["version"])))


def version_key(v):
    return [int(x) if x.isdigit() else x for x in re.split(r"[.+-]", v)]


def refusals(crates):
    out = []
    for p in crates:
        lic = p.get("license")
        if not lic:
            out.append(f"{p['name']} {p['version']}: names no SPDX licence"
                       + (f" (only {p['license_file']})" if p.get("license_file") else ""))
            continue
        try:
            ok, bad = acceptable(lic)
        except ValueError as e:
            out.append(f"{p['name']} {p['version']}: {e}")
            continue
        if not ok:
            reasons = "; ".join(f"{b}: {why_refused(b)}" for b in bad)
            out.append(f"{p['name']} {p['version']}: {lic} ({reasons})")
    return out


def render(crates):
    lines = [
        "# Third-party licences",
        "",
        "gridscada (Apache-2.0, see LICENSE and NOTICE) is built from these crates,",
        "the normal and build dependencies of its workspace for every target",
        "(dev-dependencies and test peers are not shipped). Each is used under",
        "the licence shown; where it offers a choice, under any of the permissive",
        "ones. Their licence texts ship with their sources (crates.io).",
        "",
        "Generated by `python3 scripts/licenses.py write` from `cargo metadata`;",
        "`scripts/test-all.sh` checks that it is current. Do not edit by hand.",
        "",
        "| crate | version | licence | source |",
        "|-------|---------|---------|--------|",
    ]
    for p in crates:
        lic = (p.get("license") or "").replace("|", "\\|")
        src = p.get("repository") or f"https://crates.io/crates/{p['name']}"
        lines.append(f"| {p['name']} | {p['version']} | {lic} | {src} |")
    lines.append("")
    return "\n".join(lines)


def metadata():
    out = subprocess.run(
        ["cargo", "metadata", "--format-version", "1", "--locked"],
        cwd=ROOT, check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def self_test():
    for expr, ok in [
        ("MIT", True), ("MIT OR Apache-2.0", True), ("MIT/Apache-2.0", True),
        ("Apache-2.0 WITH LLVM-exception OR Apache-2.0 OR MIT", True),
        ("(MIT OR Apache-2.0) AND Unicode-3.0", True),
        ("MIT OR GPL-3.0-only", True),          # the permissive choice is ours
        ("GPL-3.0-only", False), ("GPL-2.0+", False), ("AGPL-3.0-or-later", False),
        ("LGPL-2.1-only", False), ("LGPL-2.1-or-later OR MIT", True),
        ("MIT AND GPL-2.0-only", False), ("CC-BY-NC-4.0", False),
        ("PolyForm-Noncommercial-1.0.0", False), ("SSPL-1.0", False),
    ]:
        got = acceptable(expr)[0]
        assert got == ok, f"{expr!r}: accepted {got}, expected {ok}"
    assert why_refused("AGPL-3.0-only") == "copyleft (GPL family)"
    assert why_refused("CC-BY-NC-4.0") == "non-commercial"
    for bad in ["MIT OR", "(MIT", "AND MIT"]:
        try:
            acceptable(bad)
        except ValueError:
            continue
        raise AssertionError(f"{bad!r} was not refused as malformed")

    # The walk: a GPL crate used only by the tests is not the product's.
    def pkg(name, lic):
        return {"id": name, "name": name, "version": "1.0.0", "license": lic}

    def dep(name, kind):
        return {"pkg": name, "dep_kinds": [{"kind": kind}]}

    meta = {
        "workspace_members": ["app"],
        "packages": [pkg("app", "Apache-2.0"), pkg("serde", "MIT OR Apache-2.0"),
                     pkg("gpl-in-product", "GPL-3.0-only"), pkg("cc", "MIT"),
                     pkg("gpl-in-tests", "GPL-3.0-only"), pkg("nc", "CC-BY-NC-4.0"),
                     pkg("no-spdx", None)],
        "resolve": {"nodes": [
            {"id": "app", "deps": [dep("serde", None), dep("cc", "build"),
                                   dep("gpl-in-tests", "dev")]},
            {"id": "serde", "deps": [dep("gpl-in-product", None), dep("nc", None),
                                     dep("no-spdx", None)]},
            {"id": "cc", "deps": []}, {"id": "gpl-in-product", "deps": []},
            {"id": "gpl-in-tests", "deps": []}, {"id": "nc", "deps": []},
            {"id": "no-spdx", "deps": []},
        ]},
    }
    crates = product_crates(meta)
    assert [p["name"] for p in crates] == ["cc", "gpl-in-product", "nc", "no-spdx", "serde"], crates
    assert refusals(crates) == [
        "gpl-in-product 1.0.0: GPL-3.0-only (GPL-3.0-only: copyleft (GPL family))",
        "nc 1.0.0: CC-BY-NC-4.0 (CC-BY-NC-4.0: non-commercial)",
        "no-spdx 1.0.0: names no SPDX licence",
    ], refusals(crates)
    print("licenses: self-test passed")


def main():
    cmd = sys.argv[1] if len(sys.argv) == 2 else ""
    if cmd == "self-test":
        return self_test()
    if cmd not in ("check", "write"):
        sys.exit(__doc__.split("\n\n")[1])
    crates = product_crates(metadata())
    refused = refusals(crates)
    if refused:
        print("licenses: refused in the product's dependency tree:", file=sys.stderr)
        for r in refused:
            print(f"  {r}", file=sys.stderr)
        sys.exit(1)
    text = render(crates)
    if cmd == "write":
        with open(LIST, "w") as f:
            f.write(text)
        print(f"licenses: wrote {os.path.relpath(LIST, ROOT)} ({len(crates)} crates)")
        return
    current = open(LIST).read() if os.path.exists(LIST) else ""
    if current != text:
        sys.exit("licenses: THIRD-PARTY-LICENSES.md is not the dependency tree's: "
                 "run `python3 scripts/licenses.py write` and commit it")
    print(f"licenses: {len(crates)} crates, every licence allowed; THIRD-PARTY-LICENSES.md is current")


if __name__ == "__main__":
    main()
