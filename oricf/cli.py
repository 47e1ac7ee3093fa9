"""The `oricf` command.

    oricf serve SERVICE [--config FILE] [--overlay FILE ...]
                [--listen HOST:PORT] [--metrics-listen HOST:PORT] [--http-listen HOST:PORT]
    oricf models list | pull [NAME ...] [--all]
    oricf gateway --config PIPELINE.yaml [--overlay FILE ...]
    oricf mcp --config PIPELINE.yaml | --attach ADDRESS [--transport stdio|http]
    oricf up DEPLOYMENT.yaml
    oricf certs DIR [--host NAME ...]
    oricf demo [...]
    oricf bench detector|asr|llm|tts|voice|gateway|models|link|rtsp|offload|edge|tracking|soak
                |control|providers [...]

SERVICE is one of oricf.services.SERVICES (`oricf serve --help` lists them). Verbs with
options of their own hand the rest of the command line to their module's main().
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Callable
from pathlib import Path

from oricf.config import deep_merge, read_with_overlays, validate
from oricf.errors import ConfigError, ModelMissing
from oricf.lifeline import follow_parent
from oricf.logs import setup_logging
from oricf.services import SERVICES

log = logging.getLogger("oricf")

# verb -> module whose main(argv) -> int handles it
DELEGATED = {
    "certs": "oricf.launch.certs",
    "gateway": "oricf.gateway.shells.main",
    "mcp": "oricf.gateway.shells.mcp",
    "up": "oricf.launch.up",
    "demo": "oricf.demo.main",
}
# Modules that run a pipeline in this process: grpc's client polls in the calling thread.
RUN_PIPELINES = {"oricf.gateway.shells.main", "oricf.gateway.shells.mcp"}
BENCHMARKS = ("detector", "asr", "llm", "tts", "voice", "gateway", "models", "link", "rtsp",
              "offload", "edge", "tracking", "soak", "control", "providers")


def security_overrides(args: argparse.Namespace) -> dict[str, object]:
    """`oricf serve` flags as `server:` keys, paths made absolute (they are the shell's)."""
    server: dict[str, object] = {}
    if args.tls_cert or args.tls_key:
        tls = {"cert": args.tls_cert, "key": args.tls_key, "client_ca": args.tls_client_ca}
        server["tls"] = {k: str(Path(v).resolve()) for k, v in tls.items() if v}
    elif args.tls_client_ca:
        raise ConfigError("--tls-client-ca needs --tls-cert and --tls-key")
    if args.auth_token_file:
        server["auth"] = {"file": str(Path(args.auth_token_file).resolve())}
    if args.no_reflection:
        server["reflection"] = False
    return {"server": server} if server else {}


def metrics_overrides(args: argparse.Namespace) -> dict[str, object]:
    """--metrics-listen as `server.metrics.listen` (a `tls:` beside it in the YAML stays),
    --http-listen as `server.http.listen` (the YAML's other http keys stay)."""
    server: dict[str, object] = {}
    if args.metrics_listen:
        server["metrics"] = {"listen": args.metrics_listen}
    if args.http_listen:
        server["http"] = {"listen": args.http_listen}
    return {"server": server} if server else {}


def cmd_serve(args: argparse.Namespace) -> int:
    path = Path(args.config or SERVICES[args.service].config)
    data, sources = read_with_overlays(path, args.overlay)
    if args.service == "llm":  # before grpc, numpy or OpenCV load theirs (its docstring)
        from oricf.services.llm.preload import load_llama_first

        load_llama_first(data)

    from oricf.services import load_spec
    from oricf.services.runtime import serve
    from oricf.store import ModelStore
    from oricf.tls import check_token_sources  # grpc: loaded once a service is chosen

    spec = load_spec(args.service)
    data = deep_merge(data, security_overrides(args))
    data = deep_merge(data, metrics_overrides(args))
    config = validate(data, spec.config_schema, " + ".join(sources), base_dir=path.parent)
    check_token_sources(config, " + ".join(sources))
    model = spec.create_model(config, ModelStore())
    return serve(spec, config, model, args.listen)


def cmd_models(args: argparse.Namespace) -> int:
    from oricf.store import ModelStore

    store = ModelStore()
    if args.action == "list":
        print(f"model store: {store.root}")
        print(f"{'NAME':24} {'KIND':6} {'SIZE':>9}  {'PRESENT':8} LICENCE")
        for name in store.catalog.models:
            status = store.status(name)
            present = "yes" if status.present else ("CORRUPT" if status.problem else "no")
            size = f"{status.entry.size / 1e6:.1f} MB"
            print(f"{name:24} {status.entry.kind:6} {size:>9}  {present:8} {status.entry.license}")
        return 0
    names = list(store.catalog.models) if args.all else args.names
    if not names:
        print("name the models to pull (see `oricf models list`) or pass --all", file=sys.stderr)
        return 2
    for name in names:
        folder = store.pull(name, force=args.force)
        print(f"{name}: {folder}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="oricf", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--log-level", default=None, help="DEBUG, INFO (default), WARNING...")
    verbs = parser.add_subparsers(dest="verb", required=True)

    serve = verbs.add_parser("serve", help="run a model service")
    serve.add_argument("service", choices=list(SERVICES))
    serve.add_argument("--config", type=Path,
                       help="service YAML (default configs/services/NAME.yaml)")
    serve.add_argument("--overlay", type=Path, action="append", default=[],
                       help="YAML merged on top, e.g. configs/services/overlays/tls.yaml "
                            "(repeatable)")
    serve.add_argument("--listen", help="override the listen address, e.g. 0.0.0.0:50051")
    serve.add_argument("--tls-cert", help="serve TLS with this certificate (PEM)")
    serve.add_argument("--tls-key", help="the certificate's private key (PEM)")
    serve.add_argument("--tls-client-ca", help="require client certificates signed by this CA")
    serve.add_argument("--auth-token-file",
                       help="require `authorization: Bearer TOKEN`, one token per line")
    serve.add_argument("--no-reflection", action="store_true", help="do not serve reflection")
    serve.add_argument("--metrics-listen", metavar="HOST:PORT",
                       help="serve Prometheus metrics at http://HOST:PORT/metrics "
                            "(docs/metrics.md)")
    serve.add_argument("--http-listen", metavar="HOST:PORT",
                       help="also serve the OpenAI-compatible HTTP API there ("
                            f"{', '.join(n for n, s in SERVICES.items() if s.http)}; "
                            "docs/openai.md)")
    serve.set_defaults(run=cmd_serve)

    models = verbs.add_parser("models", help="list or fetch models into the local model store")
    models.add_argument("action", choices=["list", "pull"])
    models.add_argument("names", nargs="*")
    models.add_argument("--all", action="store_true", help="pull every catalog entry")
    models.add_argument("--force", action="store_true", help="fetch again even if present")
    models.set_defaults(run=cmd_models)

    bench = verbs.add_parser("bench", help="measure a service, the gateway or a policy's "
                             "control loop (see --help of each)")
    bench.add_argument("target", choices=BENCHMARKS)
    bench.add_argument("rest", nargs=argparse.REMAINDER)
    # oricf.bench.entry names a package a benchmark needs and lacks in one line.
    bench.set_defaults(run=lambda a: _delegate("oricf.bench.entry", [a.target, *a.rest]))

    for verb, module in DELEGATED.items():
        # No option prefix: every argument (--config ...) goes to the module's own parser.
        sub = verbs.add_parser(verb, help=f"see `oricf {verb} --help`", add_help=False,
                               prefix_chars="\0")
        sub.add_argument("rest", nargs=argparse.REMAINDER)
        sub.set_defaults(run=_delegator(module))
    return parser


def _delegator(module: str) -> Callable[[argparse.Namespace], int]:
    return lambda args: _delegate(module, args.rest)


def _delegate(module: str, argv: list[str]) -> int:
    if module in RUN_PIPELINES:
        from oricf.gateway.ros.process import poll_in_calling_thread

        poll_in_calling_thread()  # before the module's imports load grpc, which reads it once
    main: Callable[[list[str]], int] = importlib.import_module(module).main
    return main(argv)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    setup_logging(args.log_level)
    follow_parent()  # started by a launcher (oricf up, oricf demo): stop when it is gone
    try:
        return int(args.run(args) or 0)
    except (ConfigError, ModelMissing) as exc:
        log.error("%s", exc)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
