#!/usr/bin/env bash
# Runs every test suite that CI runs: set-up, lint, type check, firmware builds and native tests,
# then pytest. Every suite runs even when an earlier one fails; the exit status is non-zero when
# any failed, and the last line names them.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
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
if [ -f firmware/Makefile ]; then
  echo "== firmware (AVR image with budget, native unit tests, sanitizers, fuzzing)"
  suite firmware make -s -C firmware check
fi
echo "== batched kernels the tests use, compiled two at a time (scripts/warm_kernels.py)"
suite kernels python scripts/warm_kernels.py tests 2
echo "== pytest (two workers: pytest-xdist, a test file per worker at a time)"
suite pytest python -m pytest -n 2 --dist loadfile "$@"
if [ ${#failed[@]} -gt 0 ]; then
  echo "test: failed: ${failed[*]}" >&2
  exit 1
fi
echo "test: all suites passed"
