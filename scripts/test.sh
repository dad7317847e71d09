#!/usr/bin/env bash
# Runs every test suite that CI runs: set-up, lint, type check, firmware builds and native tests,
# then pytest. Every suite runs even when an earlier one fails; the exit status is non-zero when
# any failed, and the last line names them.
#
# The set-up compiles the batched-kernel variants the tests use (scripts/warm_kernels.py tests),
# not the main job's thirty (scripts/main.sh compiles those the first time it runs). The firmware
# suite needs only the system packages, so it runs beside the rest of the set-up (pip's install
# and the kernels' compilation) and its output is shown in its place when it has ended.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh system
fw=""
if [ -f firmware/Makefile ]; then
  # the library Python loads, first: the set-up builds it too, and the check ends with it
  make -s -C firmware native
  fw=$(mktemp -d)
  ( rc=0; make -s -C firmware check > "$fw/log" 2>&1 || rc=$?; echo "$rc" > "$fw/rc" ) &
  fwpid=$!
  trap 'wait "$fwpid" 2>/dev/null || true; rm -rf "$fw"' EXIT  # never leave it running alone
fi
bash scripts/setup.sh tests
export PATH="$(pwd)/.venv/bin:$PATH"
failed=()
suite() {  # suite NAME COMMAND...: run a suite, remember it when it fails
  local name=$1
  shift
  "$@" || failed+=("$name")
}
echo "== ruff"
suite ruff ruff check .
echo "== mypy"
suite mypy mypy sim/eelsim host/eelhost
if [ -n "$fw" ]; then
  echo "== firmware (AVR image with budget, native unit tests, sanitizers, fuzzing)"
  wait "$fwpid" || true
  cat "$fw/log"
  [ "$(cat "$fw/rc" 2>/dev/null)" = 0 ] || failed+=(firmware)
fi
echo "== pytest (two workers: pytest-xdist, a test file per worker at a time)"
suite pytest python -m pytest -n 2 --dist loadfile "$@"
if [ ${#failed[@]} -gt 0 ]; then
  echo "test: failed: ${failed[*]}" >&2
  exit 1
fi
echo "test: all suites passed"
