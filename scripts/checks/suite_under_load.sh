#!/usr/bin/env bash
# The default test suite N times in a row (default 5) beside two busy processes, as the suite's
# steadiness is judged: `bash scripts/checks/suite_under_load.sh [N]` from the project root, with the
# project's environment active. One line per run (exit code, seconds, load average, pytest's
# last line); exits 1 if any run failed.
set -u
runs=${1:-5}
python3 -c "while True: pass" & busy1=$!
python3 -c "while True: pass" & busy2=$!
trap 'kill $busy1 $busy2 2>/dev/null' EXIT
failed=0
for i in $(seq 1 "$runs"); do
  start=$(date +%s)
  log=$(mktemp)
  python -m pytest -q -p no:cacheprovider > "$log" 2>&1
  code=$?
  [ $code -ne 0 ] && failed=1
  echo "run $i: exit $code, $(( $(date +%s) - start )) s, load $(cut -d' ' -f1-3 /proc/loadavg), $(tail -1 "$log")"
  rm -f "$log"
done
exit $failed
