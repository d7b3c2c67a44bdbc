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
# Without arguments the whole suite runs at once, in three parts side by side (docs/testing.md):
# - everything but tests/autopilot on the workers, at the lowest CPU priority (nice 19): they
#   take only the CPU the real autopilots leave, so the real-autopilot tests keep the margins
#   they have on an idle machine (beside a CPU-bound worker of the same priority an ArduCopter
#   pair and PX4's use case 1 missed their deadlines on CI);
# - the real PX4 / ArduPilot tests (tests/autopilot) in two lanes, each running its tests one
#   after the other in pytests of its own (each in a network namespace of its own), its output
#   lines prefixed with its name. PX4 SIH in lockstep takes most of a core at the tests' speed
#   factors, ArduPilot SITL a fraction of one, so at most two PX4 tests run at once: one marked
#   load_tolerant and a single PX4 beside it.
#   `px4`: the tests marked px4 and load_tolerant (the PX4 serve soak, then short tests); then,
#   once the `others` lane's PX4 tests have ended, every other PX4 test.
#   `others`: the PX4 tests of $beside_soak (each a single PX4 taking about half a core, beside
#   the soak), then every test that starts no PX4.
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
    lane() {  # lane NAME MARK-EXPRESSION [PATH...]: the real-autopilot tests it selects (under
        # PATHs, by default tests/autopilot), one after the other
        local name=$1 mark=$2
        shift 2
        [ "$#" -gt 0 ] || set -- tests/autopilot
        env -u GCS_UTM_NETNS bash tests/netns.sh "$PY" -m pytest -v -p no:cacheprovider \
            -m "$mark" "$@" 2>&1 3>&- | sed -u "s/^/[$name] /"
    }
    # The PX4 tests that run beside the soak, in the `others` lane before its own tests: each
    # starts a single PX4 at a speed factor of 4-5 and takes about half a core (docs/testing.md).
    beside_soak=(tests/autopilot/test_px4_plane_landing.py tests/autopilot/test_conformance.py
        tests/autopilot/test_operator_commands.py)
    # The `others` lane tells the `px4` lane on this pipe when those have ended: opened read-write
    # here, so that writing to it never waits for the reader.
    fifo_dir="$(mktemp -d)"
    mkfifo "$fifo_dir/lanes"
    exec 3<>"$fifo_dir/lanes"
    rm -r "$fifo_dir"
    lane_pids=()
    (
        failed=0
        lane px4 "px4 and load_tolerant" || failed=1
        read -r -u 3 _  # one PX4 beside the soak at most, none beside the tests below
        lane px4 "px4 and not load_tolerant" "${beside_soak[@]/#/--ignore=}" tests/autopilot \
            || failed=1
        exit "$failed"
    ) &
    lane_pids+=("$!")
    (
        failed=0
        if [ "${#beside_soak[@]}" -gt 0 ]; then  # (empty: all of them in the `px4` lane)
            lane others "px4 and not load_tolerant" "${beside_soak[@]}" || failed=1
        fi
        echo done >&3
        lane others "not px4" || failed=1
        exit "$failed"
    ) &
    lane_pids+=("$!")
    # in the foreground: a background job would start the tests with SIGINT ignored
    # (tests/e2e/test_pilot_cli.py)
    failed=0
    nice -n 19 "${pytest[@]}" "${xdist[@]}" --ignore=tests/autopilot tests 3>&- || failed=1
    for pid in "${lane_pids[@]}"; do
        wait "$pid" || failed=1  # every lane runs to its end, failed or not
    done
    [ "$failed" -eq 0 ]
fi
