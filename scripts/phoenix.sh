#!/usr/bin/env bash
# Arize Phoenix, an OpenTelemetry backend (OTLP over gRPC and HTTP), in a virtual environment
# of its own: the `-m tracing` tests send it the gateway's and a service's traces
# (docs/testing.md, docs/tracing.md). Its dependencies (pandas, sqlalchemy, protobuf 7...)
# stay out of ORICF's environment. Runs again without reinstalling.
#
#   scripts/phoenix.sh      then ~/.cache/oricf/phoenix-venv/bin/phoenix serve
set -euo pipefail
PHOENIX_VERSION=20.26.1
CACHE="${ORICF_CACHE:-$HOME/.cache/oricf}"
VENV="$CACHE/phoenix-venv"
PYTHON="${PYTHON:-python3}"

if "$VENV/bin/python" -c "import importlib.metadata as m, sys; sys.exit(m.version('arize-phoenix') != '$PHOENIX_VERSION')" 2>/dev/null; then
    echo "Phoenix $PHOENIX_VERSION is in $VENV"
    exit 0
fi
"$PYTHON" -m venv "$VENV"
"$VENV/bin/pip" install --quiet "arize-phoenix==$PHOENIX_VERSION"
echo "Phoenix $PHOENIX_VERSION installed in $VENV ($VENV/bin/phoenix serve)"
