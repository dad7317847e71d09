#!/usr/bin/env bash
# Idempotent set-up for a fresh Debian/Ubuntu clone: system packages (when root), a virtual
# environment in .venv with eelbot and its dev tools, the native firmware library, and the twin's
# batched kernels of one set (scripts/warm_kernels.py) compiled into the kernel cache.
# Re-running it is cheap: each step is skipped when its inputs have not changed.
#
#   bash scripts/setup.sh [main|tests]   # the kernel set: main (default; scripts/main.sh) is the
#                                        # main job's thirty, tests (scripts/test.sh) the tests'
#   bash scripts/setup.sh system         # the system packages only (step 1): scripts/test.sh
#                                        # then builds the firmware beside the rest of the set-up
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
kset=${1:-main}
case $kset in
  main | tests | system) ;;
  *) echo "usage: scripts/setup.sh [main|tests|system] (the kernel set to compile; got '$kset')" >&2
     exit 2 ;;
esac

# 1. System packages (only possible as root; otherwise we report what is missing).
mapfile -t pkgs < <(grep -vE '^\s*(#|$)' scripts/apt-packages.txt)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then
    echo "setup: installing system packages: ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    echo "setup: missing system packages (run as root or install them): ${missing[*]}" >&2
  fi
fi

if [ "$kset" = system ]; then
  exit 0
fi

# 2. Python environment.
py=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  "$py" -m venv .venv
fi
stamp=.venv/.eelbot-installed
want=$(cat pyproject.toml | sha256sum | cut -c1-16)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "setup: installing eelbot and its dependencies into .venv"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -e ".[dev,bench]"
  echo "$want" > "$stamp"
fi

# 3. Native firmware library that Python loads (built by the install, see firmware/README.md).
if [ -f firmware/Makefile ]; then
  make -s -C firmware native
fi
# 4. The twin's batched kernels of the set asked for (scripts/warm_kernels.py): `main`, the main
# job's (its fits and the model comparison's candidates), or `tests`, the test suite's (the test
# command needs only those: compiling the main job's thirty too cost it about five minutes),
# compiled into the on-disk cache two at a time (the first C variant of an N about 30 s: its
# driver, which the others of that N share; they 2-3 s each; the numba stage's about 50 s; under
# a second once cached), so that the command does not pay for them; the stage compiled by the C compiler when
# there is one, else by numba. Loading a set's cached kernels to check them takes seconds of every
# run; a stamp per set in the kernel cache folder (so that emptying the folder voids it) records
# what they were built from: the twin's and the host's sources (the generator, the laws and joint
# models it reads), the installed packages, the compiler and the CPU. The stamp matching, nothing
# is loaded; a set not compiled here has no stamp, and is compiled the first time it is asked for.
cache=${EELSIM_KERNEL_CACHE:-sim/eelsim/batch/__pycache__/batch_kernels}
kstamp="$cache/.eelbot-$kset-warm"
kwant=$( { find sim/eelsim host/eelhost scripts/warm_kernels.py -name '*.py' -print0 | sort -z \
             | xargs -0 cat; cat "$stamp"; .venv/bin/python --version; cc --version 2>/dev/null;
           grep -m1 '^flags' /proc/cpuinfo 2>/dev/null; } | sha256sum | cut -c1-16)
if [ -f "$kstamp" ] && [ "$(cat "$kstamp")" = "$kwant" ]; then
  echo "setup: $kset kernels ready (cached; $kstamp)"
else
  .venv/bin/python scripts/warm_kernels.py "$kset" 2 | sed -u 's/^kernels:/setup: kernel/'
  if [ -d "$cache" ]; then echo "$kwant" > "$kstamp"; fi
fi
echo "setup: ready ($root/.venv)"
