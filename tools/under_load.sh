#!/usr/bin/env bash
# Run a pytest selection N times in a row beside a CPU hog on every core (Debian's stress-ng), and
# print how many runs passed: a check that tests which kill, signal or time processes do not race
# the machine. Each run's output goes to $LOGS/run<i>.log.
#   tools/under_load.sh N PYTEST_ARGS...     e.g.  tools/under_load.sh 10 tests/cli/test_sweeps.py
set -uo pipefail
cd "$(dirname "$0")/.."
runs=$1
shift
command -v stress-ng >/dev/null || { echo "under_load.sh needs stress-ng: apt-get install -y stress-ng"; exit 2; }
logs=${LOGS:-$(mktemp -d)}
mkdir -p "$logs"
stress-ng --cpu "$(nproc)" --quiet &
hog=$!
trap 'kill $hog 2>/dev/null' EXIT
passed=0
for i in $(seq "$runs"); do
  start=$(date +%s)
  if .venv/bin/python -m pytest -q -p no:cacheprovider "$@" >"$logs/run$i.log" 2>&1; then passed=$((passed + 1)); fi
  echo "run $i: $(tail -1 "$logs/run$i.log") ($(($(date +%s) - start)) s)"
done
echo "under_load runs=$runs passed=$passed logs=$logs"
