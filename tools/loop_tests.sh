#!/usr/bin/env bash
# Run a test target N times in a row and count the passes (flakiness check).
#   tools/loop_tests.sh [N] [TARGET]
#     N       runs (default 10)
#     TARGET  "make" = `make test` (whole suite), or a pytest path (default tests/ros)
# Each run's output goes to ${LOOP_LOG_DIR:-out/loop_tests}/run_<k>.log; prints one line per run
# and "passed P of N"; exits 0 only when every run passed.
set -u
n=${1:-10}
target=${2:-tests/ros}
here=$(cd "$(dirname "$0")/.." && pwd)
cd "$here"
py=${PYTHON:-$here/.venv/bin/python}
if [ "$target" != "make" ] && [ ! -x "$py" ]; then
    echo "loop_tests: no $py (run 'make venv' first or set PYTHON=...)" >&2
    exit 2
fi
logs=${LOOP_LOG_DIR:-out/loop_tests}
mkdir -p "$logs"
export NUMBA_CACHE_DIR=${NUMBA_CACHE_DIR:-$here/.numba_cache}
passed=0
for k in $(seq 1 "$n"); do
    start=$(date +%s)
    if [ "$target" = "make" ]; then
        make test > "$logs/run_$k.log" 2>&1
    else
        "$py" -m pytest -q -p no:cacheprovider "$target" > "$logs/run_$k.log" 2>&1
    fi
    rc=$?
    summary=$(grep -E "passed|failed|error" "$logs/run_$k.log" | tail -1)
    if [ $rc -eq 0 ]; then passed=$((passed + 1)); verdict=PASS; else verdict=FAIL; fi
    echo "run $k/$n: $verdict ($(( $(date +%s) - start )) s) $summary"
done
echo "passed $passed of $n ($target)"
[ "$passed" -eq "$n" ]
