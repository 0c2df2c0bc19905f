#!/usr/bin/env bash
# The slow tier: every test marked slow in its file (the long studies, among them the
# random-systems verdict study on sixty drawn systems, the costly repetitions and the tests
# that start processes or clusters), which CI's default run leaves out. From the project root
# with the project's environment active: `bash scripts/checks/slow_tier.sh [pytest options]`.
# Prints pytest's summary, then the wall time and the CPU time of the run (bash's `times`:
# user and system time of the children); exits with pytest's code.
set -u
start=$(date +%s)
python -m pytest -q -p no:cacheprovider -m slow "$@"
code=$?
echo "slow tier: exit $code, $(( $(date +%s) - start )) s wall; CPU (user, system) of the run:"
times | tail -1
exit $code
