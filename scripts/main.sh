#!/usr/bin/env bash
# The main job on the bundled default: set up, then simulate the paper robot swimming the turning
# experiment under its own control stack, writing the trajectory (CSV + JSON) and a plot to out/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PATH="$(pwd)/.venv/bin:$PATH"
eelbot simulate turning --plot --out out/demo/turning "$@"
