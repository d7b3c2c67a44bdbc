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
# Without arguments the whole suite runs in two steps: everything but the real autopilots on
# the workers, then the real PX4 / ArduPilot tests (tests/autopilot) one after the other with
# the machine to themselves: their timing margins assume it (beside a CPU-bound worker, an
# ArduCopter pair or PX4's use case 1 missed their deadlines on CI).
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
    "${pytest[@]}" "${xdist[@]}" --ignore=tests/autopilot tests
    echo "== pytest: real autopilots"
    "${pytest[@]}" tests/autopilot
fi
