#!/usr/bin/env bash
# The whole test suite: lint, format, types, layer contracts, then pytest.
# Usage: bash tests/check.sh [extra pytest args]
# pytest runs in a private network namespace (tests/netns.sh) where the machine allows it, so
# the real PX4 / ArduPilot SITL tests can bind their fixed ports without colliding with
# anything else; elsewhere those tests skip and say why.
set -euo pipefail
cd "$(dirname "$0")/.."
PY="${PYTHON:-.venv/bin/python}"
[ -x "$PY" ] || PY=python3
BIN="$(dirname "$PY")"

echo "== ruff check"; "$BIN/ruff" check gcs_utm adapters sitl tests setup.py
echo "== ruff format --check"; "$BIN/ruff" format --check gcs_utm adapters sitl tests setup.py
echo "== mypy --strict"; "$BIN/mypy" --strict -p gcs_utm -p adapters -p sitl
echo "== lint-imports"; "$BIN/lint-imports"
echo "== vulture"; "$BIN/vulture"  # paths and whitelist: pyproject.toml [tool.vulture]
echo "== pytest"
# pytest in GCS_UTM_TEST_JOBS parallel worker processes (pytest-xdist; 2 by default, 1 runs
# everything in this process): most of the suite's time is spent waiting on servers and
# subprocesses. Each worker gets a private network namespace of its own (tests/netns.sh).
# --dist loadgroup hands out whole modules, longest first (tests/conftest.py's scheduler;
# --no-loadscope-reorder keeps that order).
# Without arguments the whole suite runs in two steps, and the real PX4 / ArduPilot tests
# (tests/autopilot) in lanes: each lane a pytest of its own in a network namespace of its own,
# running its tests one after the other, its output lines prefixed with its name.
# 1. everything but tests/autopilot on the workers, and beside them the lane of the
#    real-autopilot tests marked load_tolerant (the PX4 serve soak: its margins were measured
#    on a loaded machine);
# 2. the other real-autopilot tests with no CPU-bound test beside them (beside a CPU-bound
#    worker, an ArduCopter pair or PX4's use case 1 missed their deadlines on CI), in two lanes
#    side by side: the tests that start a PX4 (marked px4, tests/conftest.py) and the others.
#    PX4 SIH in lockstep takes most of a core at the tests' speed factors, ArduPilot SITL a
#    fraction of one, and two PX4 tests at once missed deadlines (docs/testing.md).
jobs="${GCS_UTM_TEST_JOBS:-2}"
xdist=()
if [ "$jobs" -gt 1 ]; then
    worker="env -u GCS_UTM_NETNS bash tests/netns.sh $(printf %q "$PY")"
    xdist=(--tx "$jobs*popen//python=$worker" --dist loadgroup --no-loadscope-reorder)
fi
pytest=(bash tests/netns.sh "$PY" -m pytest -q -p no:cacheprovider)
# pytest exits 5 when it collected no test: that must fail CI, and set -e makes it so.
if [ "$#" -gt 0 ]; then
    "${pytest[@]}" "${xdist[@]}" "$@"
else
    lane() {  # lane NAME MARK-EXPRESSION: the real-autopilot tests it selects, in the background
        (env -u GCS_UTM_NETNS bash tests/netns.sh "$PY" -m pytest -v -p no:cacheprovider \
            -m "$2" tests/autopilot 2>&1 | sed -u "s/^/[$1] /") &
        lane_pids+=("$!")
    }
    lanes_wait() {  # fails when a lane failed, after all of them ended
        local failed=0 pid
        for pid in "${lane_pids[@]}"; do
            wait "$pid" || failed=1
        done
        lane_pids=()
        return "$failed"
    }
    lane_pids=()
    lane beside-the-rest "load_tolerant"
    step1=0
    "${pytest[@]}" "${xdist[@]}" --ignore=tests/autopilot tests || step1=$?
    lanes_wait
    [ "$step1" -eq 0 ]
    echo "== pytest: real autopilots, a PX4 lane beside the others"
    lane px4 "px4 and not load_tolerant"
    lane others "not px4 and not load_tolerant"
    lanes_wait
fi
