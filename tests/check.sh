#!/usr/bin/env bash
# The whole test suite: lint, format, types, layer contracts, then pytest.
# Usage: bash tests/check.sh [extra pytest args]
set -euo pipefail
cd "$(dirname "$0")/.."
PY="${PYTHON:-.venv/bin/python}"
[ -x "$PY" ] || PY=python3
BIN="$(dirname "$PY")"

echo "== ruff check"; "$BIN/ruff" check gcs_utm adapters sitl tests setup.py
echo "== ruff format --check"; "$BIN/ruff" format --check gcs_utm adapters sitl tests setup.py
echo "== mypy --strict"; "$BIN/mypy" --strict -p gcs_utm -p adapters -p sitl
echo "== lint-imports"; "$BIN/lint-imports"
echo "== pytest"
# pytest exits 5 when it collected no test: that must fail CI, and set -e makes it so.
"$PY" -m pytest -q -p no:cacheprovider "$@"
