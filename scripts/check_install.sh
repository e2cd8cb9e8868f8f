#!/usr/bin/env bash
# `pip install .` (not editable) into a fresh virtual environment, then the quick reproduction
# run from another folder: the package must carry everything it needs (scenes, targets).
# Used by `make test` (and so by CI). Leaves nothing behind.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
PYTHON="${PYTHON:-python3}"
"$PYTHON" -m venv "$work/venv"
"$work/venv/bin/python" -m pip install -q --upgrade pip
"$work/venv/bin/python" -m pip install -q "$repo"
cd "$work"
"$work/venv/bin/bench-sim" reproduce --quick --out "$work/out" >"$work/log" 2>&1 || { cat "$work/log"; exit 1; }
for f in report.md metrics.json fig3_stages.png fig4_hdr.png snr_vs_signal.png table1.csv; do
  [ -s "$work/out/$f" ] || { echo "check_install: $f missing from the installed package's run"; exit 1; }
done
echo "check_install: pip install . into a fresh venv runs 'bench-sim reproduce --quick' from another folder"
