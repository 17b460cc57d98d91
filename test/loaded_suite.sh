#!/usr/bin/env bash
# The suite on a loaded machine: every core kept busy by a bounded CPU hog while pytest runs,
# RUNS times (default 3). A test that fails only here stands a wall-clock bound for "it
# worked": it should wait for its event with a generous limit instead.
#
#   test/loaded_suite.sh                      # the whole default suite, 3 runs
#   RUNS=1 test/loaded_suite.sh test/test_ros_execution.py -k stop   # chosen tests
#
# Environment: RUNS (runs, default 3), HOGS (busy processes, default: the cores),
# HOG_S (s each hog lives at most, default 3600), PYTHON (default .venv/bin/python),
# LOGS (folder of each run's output, default a new one in /tmp).
# Each run's outcome and wall time are printed; the exit code is the number of failed runs.
# SIGINT or SIGTERM stops the run in progress and the hogs, and ends the script.
set -u
cd "$(dirname "$0")/.."
RUNS=${RUNS:-3}
HOGS=${HOGS:-$(nproc)}
HOG_S=${HOG_S:-3600}
PYTHON=${PYTHON:-.venv/bin/python}
# the environment `make test` exports (Makefile), so a run here is the CI's run under load
export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
export AMENT_PREFIX_PATH=${AMENT_PREFIX_PATH:-$PWD/.venv}
LOGS=${LOGS:-$(mktemp -d /tmp/loaded_suite.XXXXXX)}   # each run's pytest output
mkdir -p "$LOGS"
hogs=()
suite=""

stop_hogs() {
    for pid in "${hogs[@]}"; do kill "$pid" 2>/dev/null; done
    for pid in "${hogs[@]}"; do wait "$pid" 2>/dev/null; done
    hogs=()
}
stop_all() {   # SIGINT / SIGTERM: the run in progress (pytest stops its workers) and the hogs
    [ -n "$suite" ] && kill -TERM "$suite" 2>/dev/null && wait "$suite" 2>/dev/null
    stop_hogs
}
trap stop_hogs EXIT
trap 'stop_all; exit 130' INT
trap 'stop_all; exit 143' TERM

failed=0
for run in $(seq 1 "$RUNS"); do
    for _ in $(seq 1 "$HOGS"); do   # each hog bounded by timeout, killed by its PID after
        timeout "$HOG_S" "$PYTHON" -c "while True: pass" &
        hogs+=($!)
    done
    start=$(date +%s)
    # in the background and waited for, so that a signal to this script is handled at once
    "$PYTHON" -m pytest -p no:cacheprovider "$@" > "$LOGS/run$run.log" 2>&1 &
    suite=$!
    wait "$suite"
    rc=$?
    suite=""
    end=$(date +%s)
    stop_hogs
    summary=$(grep -E "passed|failed|error" "$LOGS/run$run.log" | tail -1)
    echo "run $run of $RUNS ($HOGS hogs): exit $rc in $((end - start)) s: $summary"
    [ "$rc" -eq 0 ] || failed=$((failed + 1))
done
exit "$failed"
