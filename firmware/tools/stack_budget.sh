#!/bin/sh
# Static RAM plus the deepest stack measured in simavr (the "stack peak" lines of eel_avrsim's
# reports, painted and scanned) against a limit: 2048 B of RAM less 256 B kept free.
# usage: stack_budget.sh SIZE_TXT LIMIT_BYTES REPORT...
set -eu
size=$1 limit=$2
shift 2
ram=$(sed -n 's/^static RAM: \([0-9]*\) bytes.*/\1/p' "$size")
peak=0
for f in "$@"; do
  p=$(sed -n 's/^stack peak: \([0-9]*\) bytes.*/\1/p' "$f")
  [ -n "$p" ] && [ "$p" -gt "$peak" ] && peak=$p
done
total=$((ram + peak))
echo "RAM: static $ram + stack peak $peak = $total bytes of $limit limit (chip 2048, $((2048 - total)) free)"
if [ "$peak" -eq 0 ] || [ "$total" -gt "$limit" ]; then
  echo "FAIL: static RAM plus the stack's peak exceeds $limit bytes (or no peak measured)"
  exit 1
fi
