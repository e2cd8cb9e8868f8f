#!/usr/bin/env bash
# `make test` (and so CI): the linters, the test suite on every core and the install check.
# The install check (scripts/check_install.sh: pip, then one quick run) runs beside the other two;
# its last line follows theirs (all of its output if it fails). Any of the three failing fails the
# whole. Arguments go to pytest.
# The suite: pytest-xdist on every core (`-n auto`; PYTEST_XDIST_AUTO_NUM_WORKERS=N for another
# count), each test file on one worker (`--dist loadfile`: a module-scoped fixture, such as a
# `reproduce --quick` run, is computed once), a skip failing unless listed in
# tests/allowed_skips.txt (`--strict-skips`, tests/skip_guard.py); the full signal stress series
# (marker `stress`, about 35 minutes) is left to `make test-stress`.
set -uo pipefail
cd "$(dirname "$0")/.."
log="$(mktemp)"
trap 'rm -f "$log"' EXIT
bash scripts/check_install.sh >"$log" 2>&1 &
install=$!
status=0
make --no-print-directory lint || status=$?
if [ "$status" -eq 0 ]; then
  .venv/bin/python -m pytest -n auto --dist loadfile --strict-skips -m "not stress" "$@" || status=$?
fi
if wait "$install"; then
  tail -n 1 "$log"
else
  rc=$?
  cat "$log"
  echo "check_install: failed (exit status $rc)"
  [ "$status" -ne 0 ] || status=$rc
fi
exit "$status"
