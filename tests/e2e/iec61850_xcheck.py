#!/usr/bin/env python3
"""Read IEC 61850 values with open61850 (Apache-2.0, pure Python), an MMS client
independent of both libiec61850 and gridscada, and print them as one JSON object.

    python3 iec61850_xcheck.py --port P [--host 127.0.0.1] --refs 'TESTLD0/MMXU1.TotW.mag.f[MX]' ...
    python3 iec61850_xcheck.py --port P --all      # every leaf found by GetNameList (FC CO excluded)

Keys are the references as given (with --all: ``LD/LN.DO.DA[FC]``). Values use the
conventions of iec61850_peer.py so the two can be compared directly: bool, int,
float, str (visible string), hex (octet string), unix float seconds (utc-time),
Dbpos as int 0..3 (for a 2-bit ``stVal``), Quality as libiec61850's int (bit i of the
bit-string = bit i; for ``q``), other bit-strings as '0101' text, a structure as a
list of its members, and a refused read as {"error": "..."}.
"""

from __future__ import annotations

import argparse
import json
import sys

from open61850.data import (ArrayData, BitStringData, BoolData, FloatData, IntData, MmsStringData,
                            OctetStringData, StructureData, TimestampData, UIntData, VisibleStringData)
from open61850.mms import MmsClient
from open61850.mms.model import discover


def _bits(b: BitStringData) -> list[int]:
    n = len(b.value) * 8 - b.unused_bits
    return [(b.value[i // 8] >> (7 - i % 8)) & 1 for i in range(n)]


def to_json(v, leaf: str = ""):
    if isinstance(v, BoolData):
        return bool(v.value)
    if isinstance(v, (IntData, UIntData)):
        return int(v.value)
    if isinstance(v, FloatData):
        return float(v.value)
    if isinstance(v, TimestampData):
        return v.value.timestamp()
    if isinstance(v, (VisibleStringData, MmsStringData)):
        return v.value
    if isinstance(v, OctetStringData):
        return v.value.hex()
    if isinstance(v, BitStringData):
        bits = _bits(v)
        if leaf == "stVal" and len(bits) == 2:
            return bits[0] * 2 + bits[1]
        if leaf == "q":
            return sum(bit << i for i, bit in enumerate(bits))
        return "".join(map(str, bits))
    if isinstance(v, StructureData):
        return [to_json(m) for m in v.members]
    if isinstance(v, ArrayData):
        return [to_json(m) for m in v.elements]
    if isinstance(v, Exception):
        return {"error": str(v)}
    return {"raw": repr(v)}


def _leaf_name(ref: str) -> str:
    base = ref.split("[", 1)[0].strip()
    return base.replace("$", ".").split("/")[-1].split(".")[-1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=102)
    ap.add_argument("--refs", nargs="*", default=[], help="references like LD/LN.DO.DA[FC]")
    ap.add_argument("--all", action="store_true", help="every leaf of the server's directory (not CO)")
    ap.add_argument("--timeout", type=float, default=10.0)
    args = ap.parse_args(argv)

    out: dict = {}
    try:
        with MmsClient.connect(args.host, args.port, timeout=args.timeout) as c:
            refs = list(args.refs)
            if args.all:
                model = discover(c)
                for r in model.references():
                    if r.fc in (None, "CO"):
                        continue
                    refs.append(f"{r.name}[{r.fc}]")
            for ref in refs:
                try:
                    out[ref] = to_json(c.read(ref), _leaf_name(ref))
                except Exception as e:  # a refused read is a value for the comparison
                    out[ref] = {"error": f"{type(e).__name__}: {e}"}
    except Exception as e:
        print(json.dumps({"error": f"{type(e).__name__}: {e}"}))
        return 1
    print(json.dumps(out, sort_keys=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
