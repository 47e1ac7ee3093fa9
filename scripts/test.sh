#!/usr/bin/env bash
# Sets up everything the tests need (scripts/setup.sh --dev), checks style and types,
# then runs the whole test suite against the real models.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh --dev
VENV="${ORICF_VENV:-.venv}"
echo; echo "==> ruff"
"$VENV/bin/ruff" check .
echo; echo "==> mypy"
"$VENV/bin/mypy" oricf services gateway bench
echo; echo "==> pytest"
exec "$VENV/bin/python" -m pytest "$@"
