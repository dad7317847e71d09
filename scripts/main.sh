#!/usr/bin/env bash
# The main job on the bundled default: set up, then fit the hydrodynamic coefficients of the paper
# robot to the bundled virtual-tank dataset (straight and turning, CMA-ES with restarts + minimax polish),
# validate them on the held-out experiments and paths, and write the report folder out/report/
# (report.md, tables, figures, coefficients with bootstrap uncertainty, identifiability, warnings
# and the comparison of candidate models).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PATH="$(pwd)/.venv/bin:$PATH"
eelbot report --out out/report "$@"
