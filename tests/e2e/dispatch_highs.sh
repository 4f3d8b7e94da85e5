#!/usr/bin/env bash
# Dispatch optimality against an independent solver: HiGHS (highspy) on 200
# random single-period and 50 multi-period instances, fixed seed.
set -euo pipefail
cd "$(dirname "$0")/../.."
exec python3 tests/dispatch/compare_highs.py "${GRIDSCADA_BIN:-target/debug/gridscada}"
