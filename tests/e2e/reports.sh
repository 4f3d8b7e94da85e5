#!/usr/bin/env bash
# The daily report against a replayed night whose totals are known
# (scenarios/report-known-day.toml): replay it keeping its database, make the
# report with `gridscada report`, check the figures, then print the HTML to
# PDF with Chromium and check the PDF's text (pdftotext) and its first page
# turned into PNG (pdftoppm) for ink. Artifacts in tests/e2e/artifacts/reports/.
#   GRIDSCADA_BIN  the binary (default: target/release/gridscada, else target/debug/gridscada)
#   PYTHON         a Python with Pillow (default: target/test-venv/bin/python)
set -euo pipefail
cd "$(dirname "$0")/../.."
bin="${GRIDSCADA_BIN:-}"
if [ -z "$bin" ]; then
    if [ -x target/release/gridscada ]; then bin=target/release/gridscada; else bin=target/debug/gridscada; fi
fi
python="${PYTHON:-target/test-venv/bin/python}"
out=tests/e2e/artifacts/reports
rm -rf "$out"
mkdir -p "$out"
data="$out/data"

echo "reports.sh: replaying scenarios/report-known-day.toml"
RUST_LOG=warn "$bin" replay scenarios/report-known-day.toml --max --no-compare --data "$data" \
    >"$out/replay.txt" 2>"$out/replay.log"
RUST_LOG=warn "$bin" report 2024-06-21 --data "$data" >"$out/report.txt"
html="$data/reports/2024-06-21.html"
for f in html csv json; do
    [ -s "$data/reports/2024-06-21.$f" ] || { echo "reports.sh: no $f report" >&2; exit 1; }
done
head -1 "$data/reports/2024-06-21.csv" | grep -qx 'section,subject,figure,value,unit'

echo "reports.sh: printing the HTML report to PDF with Chromium"
chromium --headless --no-sandbox --disable-gpu --no-pdf-header-footer \
    --print-to-pdf="$out/report.pdf" "file://$PWD/$html" >"$out/chromium.log" 2>&1
[ -s "$out/report.pdf" ] || { echo "reports.sh: Chromium wrote no PDF" >&2; cat "$out/chromium.log" >&2; exit 1; }
pdftotext -layout "$out/report.pdf" "$out/report.txt"
pdftoppm -f 1 -l 1 -r 60 -png "$out/report.pdf" "$out/page"
png=$(ls "$out"/page*.png | head -1)

"$python" tests/e2e/reports_check.py "$data/reports/2024-06-21.json" "$out/report.pdf" "$png" "$out/report.txt"
