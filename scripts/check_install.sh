#!/usr/bin/env bash
# `pip install .` (not editable) into a fresh virtual environment, then the quick reproduction
# run from another folder: the package must carry everything it needs (scenes, targets).
# Used by `make test` (and so by CI), beside the test suite. Leaves nothing behind.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
PYTHON="${PYTHON:-python3}"
"$PYTHON" -m venv "$work/venv"
"$work/venv/bin/python" -m pip install -q --upgrade pip
# pip builds a local folder in place (build/, bench_sim.egg-info/): build a copy of the sources, so
# that nothing in the repository changes while `make test` runs the suite beside this check
mkdir "$work/src"
tar -C "$repo" --exclude=./.git --exclude=./.venv --exclude=./build --exclude=./results \
  --exclude='*.egg-info' --exclude=__pycache__ --exclude='.*_cache' -cf - . | tar -C "$work/src" -xf -
"$work/venv/bin/python" -m pip install -q "$work/src"
cd "$work"
"$work/venv/bin/bench-sim" reproduce --quick --out "$work/out" >"$work/log" 2>&1 || { cat "$work/log"; exit 1; }
for f in report.md metrics.json fig3_stages.png fig4_hdr.png snr_vs_signal.png table1.csv; do
  [ -s "$work/out/$f" ] || { echo "check_install: $f missing from the installed package's run"; exit 1; }
done
echo "check_install: pip install . into a fresh venv runs 'bench-sim reproduce --quick' from another folder"
