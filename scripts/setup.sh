#!/usr/bin/env bash
# One-time set-up on a fresh Debian 12 machine: the LLVM library Dr.Jit needs, and a virtual
# environment with bench_sim installed in it. Safe to run again; it only does what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

# Dr.Jit 1.5's LLVM backend aborts the process with Debian 12's libLLVM 15/16 ("Cannot select:
# fminimum"); libLLVM 19 works. bench_sim.runtime.backend finds and probes it at run time.
if ! ls /usr/lib/*-linux-gnu/libLLVM.so.19* >/dev/null 2>&1 \
   && ! ls /usr/lib/*-linux-gnu/libLLVM-19.so* >/dev/null 2>&1; then
  SUDO=""
  if [ "$(id -u)" != "0" ]; then SUDO="sudo"; fi
  echo "setup: installing libllvm19 (Debian package) for Dr.Jit's LLVM backend"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libllvm19 >/dev/null
fi

PYTHON="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[dev]"
# Byte-compile the package now (an editable install does not): start-up then reads the cached
# bytecode even where PYTHONDONTWRITEBYTECODE is set (`bench-sim --help` in about half the time).
.venv/bin/python -m compileall -q bench_sim >/dev/null
echo "setup: done ($(.venv/bin/python -c 'import bench_sim; print("bench_sim", bench_sim.__version__)'))"
