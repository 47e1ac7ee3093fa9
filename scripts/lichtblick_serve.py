"""Serves a Lichtblick web build (scripts/lichtblick.sh builds it) over HTTP with a layout:
`python scripts/lichtblick_serve.py WEB_DIR [--listen 127.0.0.1:8080] [--layout FILE]
[--tls-cert FILE --tls-key FILE]`.

The web build's index.html has a placeholder for a default layout (the one Lichtblick's own
Docker image fills from /lichtblick/default-layout.json); it is filled here with the layout
file (docs/live-view-layout.json by default), so a browser without a layout of its own opens
with the live view's panels. The connection goes in the URL:
`http://127.0.0.1:8080/?ds=foxglove-websocket&ds.url=ws://127.0.0.1:8765`.

It listens as ORICF's listeners do (oricf.hosts): a bare port (`8080`, `:8080`) is
127.0.0.1, and an address other machines reach needs TLS (--tls-cert, --tls-key), as the
page's URL carries the live view's address and its token. What it serves is the build's
files (Starlette's StaticFiles): from inside the folder only (a link leading out of it is
not followed), never a folder's listing, and 400 for a path holding a NUL. Its connections
follow every ORICF HTTP listener's rules (uvicorn, oricf.http_connections): at most
MAX_CONNECTIONS, a deadline for a request's headers, idle ones closed to make room.
"""

from __future__ import annotations

import argparse
import json
import logging
import mimetypes
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import uvicorn
from starlette.applications import Starlette
from starlette.exceptions import HTTPException
from starlette.requests import Request
from starlette.responses import Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles
from starlette.types import Scope

from oricf.errors import ConfigError
from oricf.hosts import Address, listen_address
from oricf.http_connections import guarded_h11
from oricf.tls import ServerTls

log = logging.getLogger(__name__)

PLACEHOLDER = "/*LICHTBLICK_SUITE_DEFAULT_LAYOUT_PLACEHOLDER*/"
LAYOUT = Path(__file__).resolve().parent.parent / "docs" / "live-view-layout.json"
# One browser opens a few dozen connections at most; more get 503 at once.
MAX_CONNECTIONS = 64
HEADER_TIMEOUT_S = 10.0
KEEP_ALIVE_S = 5
START_TIMEOUT_S = 10.0
ANY_LOOPBACK_PORT = Address("127.0.0.1", 0)
# Whatever the system's mime.types says: a browser compiles WebAssembly as it streams in
# only when it comes as application/wasm.
TYPES = {".wasm": "application/wasm", ".js": "text/javascript"}


def index_with_layout(web: Path, layout: Path) -> bytes:
    """The build's index.html with `layout` as its default layout."""
    html = (web / "index.html").read_text()
    if PLACEHOLDER not in html:
        raise SystemExit(f"{web}/index.html has no default-layout placeholder: not a "
                         "Lichtblick web build (run scripts/lichtblick.sh)")
    data = json.dumps(json.loads(layout.read_text()))  # checked, on one line
    return html.replace(PLACEHOLDER, data).encode()


class WebFolder(StaticFiles):
    """The build's files, inside its folder only (links resolved, then checked to be in
    it), a folder answered 404 (StaticFiles lists none outside html mode), a path with a
    NUL 400."""

    def __init__(self, web: Path) -> None:
        super().__init__(directory=web, follow_symlink=False)

    def get_path(self, scope: Scope) -> str:
        if "\x00" in scope["path"]:
            raise HTTPException(400, "a path may not hold a NUL byte")
        return super().get_path(scope)


def app(web: Path, layout: Path = LAYOUT) -> Starlette:
    """`/` and `/index.html`: the page with the layout; any other path, a file of the build."""
    index = index_with_layout(web, layout)
    for suffix, kind in TYPES.items():
        mimetypes.add_type(kind, suffix)

    async def page(request: Request) -> Response:
        return Response(index, media_type="text/html")

    return Starlette(routes=[Route("/", page), Route("/index.html", page),
                             Mount("/", WebFolder(web))])


def listener(listen: str, tls: ServerTls | None) -> Address:
    """The address `--listen` names, refused beyond loopback without TLS."""
    try:
        address = listen_address(listen)
    except ValueError as exc:
        raise ConfigError(f"--listen: {exc}") from None
    if not address.is_loopback and tls is None:
        raise ConfigError(f"--listen {address} is reachable from other machines: it needs "
                          f"--tls-cert and --tls-key (the page's URL carries the live view's "
                          f"token), or listen on 127.0.0.1")
    return address


def server_tls(cert: Path | None, key: Path | None) -> ServerTls | None:
    """--tls-cert and --tls-key, both or neither, loaded once here to name them if they
    cannot be."""
    if cert is None and key is None:
        return None
    if cert is None or key is None:
        raise ConfigError("--tls-cert and --tls-key: give both or neither")
    tls = ServerTls.model_construct(cert=cert, key=key, client_ca=None)
    tls.ssl_context("--tls-cert, --tls-key")
    return tls


def bind(address: Address) -> socket.socket:
    family = socket.AF_INET6 if ":" in address.host else socket.AF_INET
    return socket.create_server((address.host, address.port), family=family)


def server(web: Path, layout: Path = LAYOUT, tls: ServerTls | None = None) -> uvicorn.Server:
    """uvicorn for the build in `web` (not yet serving; its socket is given to run)."""
    return uvicorn.Server(uvicorn.Config(
        app(web, layout), lifespan="off", log_level="warning",
        http=guarded_h11(HEADER_TIMEOUT_S), limit_concurrency=MAX_CONNECTIONS,
        timeout_keep_alive=KEEP_ALIVE_S,
        ssl_certfile=str(tls.cert) if tls else None, ssl_keyfile=str(tls.key) if tls else None))


@contextmanager
def serving(web: Path, layout: Path = LAYOUT, address: Address = ANY_LOOPBACK_PORT
            ) -> Iterator[str]:
    """The build served (by default on 127.0.0.1 at a free port) while the block runs: its
    base URL."""
    httpd = server(web, layout)
    sock = bind(address)
    thread = threading.Thread(target=httpd.run, kwargs={"sockets": [sock]}, daemon=True,
                              name="lichtblick")
    thread.start()
    deadline = time.monotonic() + START_TIMEOUT_S
    while not httpd.started and thread.is_alive() and time.monotonic() < deadline:
        time.sleep(0.02)
    try:
        if not httpd.started:
            raise OSError(f"the Lichtblick server did not start within {START_TIMEOUT_S} s")
        yield f"http://{Address(address.host, sock.getsockname()[1])}"
    finally:
        httpd.should_exit = True
        thread.join(timeout=10)
        sock.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("web", type=Path, help="the web build (its index.html)")
    parser.add_argument("--listen", default="127.0.0.1:8080",
                        help="HOST:PORT, or a port on 127.0.0.1 (default 127.0.0.1:8080)")
    parser.add_argument("--layout", type=Path, default=LAYOUT, help="a Lichtblick layout")
    parser.add_argument("--tls-cert", type=Path, help="serve HTTPS with this certificate")
    parser.add_argument("--tls-key", type=Path, help="the certificate's private key")
    parser.add_argument("--view", default="ws://127.0.0.1:8765",
                        help="the live view's address, for the URL printed")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        tls = server_tls(args.tls_cert, args.tls_key)
        address = listener(args.listen, tls)
        httpd = server(args.web, args.layout, tls)
        sock = bind(address)
    except (ConfigError, OSError) as exc:
        log.error("%s", exc)
        return 2
    bound = Address(address.host, sock.getsockname()[1])
    log.info("Lichtblick at %s://%s/?ds=foxglove-websocket&ds.url=%s (Ctrl-C stops)",
             "https" if tls else "http", bound, args.view)
    httpd.run(sockets=[sock])  # until SIGINT or SIGTERM
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
