#!/usr/bin/env bash
# Runs every test suite that CI runs: set-up, lint, firmware builds and native tests, then pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PATH="$(pwd)/.venv/bin:$PATH"
echo "== ruff"
ruff check .
if [ -f firmware/Makefile ]; then
  echo "== firmware (AVR image with budget, native unit tests, sanitizers, fuzzing)"
  make -s -C firmware check
fi
echo "== pytest"
python -m pytest "$@"
