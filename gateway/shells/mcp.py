"""`oricf mcp`: the gateway as a Model Context Protocol server, for LLM agents.

    oricf mcp --config PIPELINE.yaml [--overlay FILE ...] [--set KEY=VALUE ...]
        runs the pipeline in this process and serves MCP on standard input and output,
        which is how a desktop agent launches a server (docs/agents.md has its JSON);
    oricf mcp --attach unix:/run/oricf/control.sock | https://HOST:PORT [--token-file F]
        serves a gateway that already runs (its `control:` API) instead;
    --transport http [--listen 127.0.0.1:8765] [--auth-token-file F] [--tls-cert C --tls-key K]
        serves MCP over streamable HTTP at http(s)://LISTEN/mcp instead of stdio: loopback
        by default; any other address needs tokens and TLS.

Tools: list_products, read_product, look, detect, infer, ask, transcribe, say, status, and
publish, which writes only to the targets of the pipeline's `agent:` policy (bounds, rate,
approval, deadman). Every call goes to the audit log (`agent.audit`, or --audit).
With stdio, standard output carries the protocol alone: logs go to standard error, and a
pipeline that writes its outputs to standard output is refused.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import anyio

from oricf.errors import ConfigError, NotReady
from oricf.gateway.actuation.audit import AuditLog
from oricf.gateway.agents.http import HttpSettings, serve_http
from oricf.gateway.agents.mcp_server import build_server
from oricf.gateway.agents.stdio import serve_stdio
from oricf.gateway.config import PipelineConfig, load_pipeline
from oricf.gateway.operations.api import Operations
from oricf.metrics import MetricsConfig, MetricsServer
from oricf.tls import check_token_sources

log = logging.getLogger(__name__)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="oricf mcp", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--config", type=Path, help="pipeline YAML to run in this process")
    where.add_argument("--attach", metavar="ADDRESS",
                       help="a running gateway's control API: unix:PATH or http(s)://HOST:PORT")
    parser.add_argument("--overlay", type=Path, action="append", default=[],
                        help="--config: YAML merged on top (repeatable)")
    parser.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                        help="--config: override a pipeline key (repeatable)")
    parser.add_argument("--token-file", type=Path,
                        help="--attach: the control API's bearer token (first line)")
    parser.add_argument("--ca", type=Path, help="--attach https: the CA of its certificate")
    parser.add_argument("--audit", type=Path,
                        help="JSON lines of every tool call (default: the policy's "
                             "agent.audit with --config)")
    parser.add_argument("--metrics-listen", metavar="HOST:PORT",
                        help="serve the agent's Prometheus counters at "
                             "http://HOST:PORT/metrics (oricf_agent_calls_total)")
    parser.add_argument("--transport", choices=["stdio", "http"], default="stdio")
    parser.add_argument("--listen", default="127.0.0.1:8765",
                        help="--transport http: HOST:PORT (default 127.0.0.1:8765)")
    parser.add_argument("--auth-token-file", type=Path,
                        help="--transport http: require `Authorization: Bearer TOKEN`, one "
                             "token per line")
    parser.add_argument("--tls-cert", type=Path, help="--transport http: serve HTTPS")
    parser.add_argument("--tls-key", type=Path, help="--transport http: the key of --tls-cert")
    parser.add_argument("--max-request-bytes", type=int, default=16 * 1024 * 1024,
                        help="--transport http: the largest request body (default 16 MiB)")
    return parser


def check_stdio(config: PipelineConfig) -> None:
    """Standard output is the protocol: no output of the pipeline may write there."""
    for name, route in config.routes.items():
        for i, output in enumerate(route.outputs):
            if "-" in (output.jsonl, output.text):
                raise ConfigError(f"routes.{name}.outputs[{i}]: writes to standard output, "
                                  f"which carries the MCP protocol; send it to a file")
        if route.input.text == "-":
            raise ConfigError(f"routes.{name}.input.text: reads standard input, which "
                              f"carries the MCP protocol")


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    http = HttpSettings.from_args(args) if args.transport == "http" else None
    if args.attach:
        from oricf.gateway.operations.client import ControlClient

        gateway: Operations = ControlClient(args.attach, args.token_file, args.ca)
        try:
            gateway.status()  # fail now, with the reason, if the gateway cannot be reached
        except NotReady as exc:
            log.error("%s", exc)
            return 2
        return serve(gateway, AuditLog(args.audit), http, args.metrics_listen)
    config = load_pipeline(args.config, args.overlay, sets=args.sets)
    check_token_sources(config, config.origin)
    if http is None:
        check_stdio(config)
    from oricf.gateway.shells.embedded import EmbeddedGateway

    embedded = EmbeddedGateway(config, audit_path=args.audit)
    view = embedded.start()
    try:
        return serve(view, view.audit, http, args.metrics_listen)
    finally:
        embedded.stop()


def serve(gateway: Operations, audit: AuditLog, http: HttpSettings | None,
          metrics_listen: str | None = None) -> int:
    app = build_server(gateway, audit)
    metrics = (MetricsServer(MetricsConfig(listen=metrics_listen), audit.registry)
               if metrics_listen else None)
    try:
        if http is None:
            log.info("MCP on standard input and output")
            anyio.run(serve_stdio, app)
        else:
            serve_http(app, http)
    finally:
        if metrics is not None:
            metrics.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
