#!/usr/bin/env python3
"""A replayed day's perfect-foresight optimum checked against HiGHS.

`gridscada replay` computes the optimum of the day it replayed with its own
commitment search (branch and bound over clarabel relaxations) and, with
GRIDSCADA_FORESIGHT_OUT set, writes that day's problem in the
`gridscada dispatch solve` format. This script solves the same problem as a
MILP with HiGHS (the model of compare_highs.py, formulated independently from
docs/DISPATCH.md) and checks:

- gridscada's optimum is a real schedule: never cheaper than HiGHS's optimum;
- gridscada's lower bound is a real bound: never above HiGHS's optimum;
- the realized cost of the day is within the scenario's `optimum_ratio`
  expectation of HiGHS's optimum too, so the verdict does not rest on our own
  solver alone.

Usage: foresight_highs.py REPORT.json PROBLEM.json
Prints one line and exits 1 on a failed check.
"""

import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import compare_highs  # noqa: E402

REL = 1e-4


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    report = json.load(open(sys.argv[1]))
    problem = json.load(open(sys.argv[2]))
    status, highs, ms = compare_highs.highs_commit(problem)
    if status != "optimal":
        print(f"HiGHS: {status}")
        sys.exit(1)
    f = report["figures"]
    ours, bound, realized = f.get("optimum_cost"), f.get("optimum_lower_bound"), f["total_cost"]
    tol = REL * max(1.0, abs(highs))
    failures = []
    if ours is not None and ours < highs - tol:
        failures.append(f"gridscada's optimum {ours:.4f} is below HiGHS's {highs:.4f}")
    if bound is not None and bound > highs + tol:
        failures.append(f"gridscada's lower bound {bound:.4f} is above HiGHS's optimum {highs:.4f}")
    limit = None
    for e in report["expectations"]:
        if e["expected"].startswith("optimum_ratio <= "):
            limit = float(e["expected"].split("<=")[1])
    ratio = realized / highs if highs > 0 else float("nan")
    if limit is not None and not ratio <= limit:
        failures.append(f"realized / HiGHS optimum {ratio:.4f} exceeds {limit}")
    print(f"realized {realized:.2f} / HiGHS optimum {highs:.2f} = {ratio:.4f}"
          + (f" (limit {limit})" if limit is not None else "")
          + (f"; gridscada's optimum {ours:.2f} ({ours / highs:.4f} of HiGHS's)" if ours else "")
          + (f", bound {bound:.2f}" if bound is not None else "")
          + f"; HiGHS {ms:.0f} ms")
    for x in failures:
        print("FAILED: " + x)
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
