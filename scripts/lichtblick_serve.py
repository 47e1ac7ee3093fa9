"""Serves a Lichtblick web build (scripts/lichtblick.sh builds it) over HTTP with a layout:
`python scripts/lichtblick_serve.py WEB_DIR [--listen 127.0.0.1:8080] [--layout FILE]`.

The web build's index.html has a placeholder for a default layout (the one Lichtblick's own
Docker image fills from /lichtblick/default-layout.json); it is filled here with the layout
file (docs/live-view-layout.json by default), so a browser without a layout of its own opens
with the live view's panels. The connection goes in the URL:
`http://127.0.0.1:8080/?ds=foxglove-websocket&ds.url=ws://127.0.0.1:8765`.
"""

from __future__ import annotations

import argparse
import functools
import json
import logging
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

log = logging.getLogger(__name__)

PLACEHOLDER = "/*LICHTBLICK_SUITE_DEFAULT_LAYOUT_PLACEHOLDER*/"
LAYOUT = Path(__file__).resolve().parent.parent / "docs" / "live-view-layout.json"


def index_with_layout(web: Path, layout: Path) -> bytes:
    """The build's index.html with `layout` as its default layout."""
    html = (web / "index.html").read_text()
    if PLACEHOLDER not in html:
        raise SystemExit(f"{web}/index.html has no default-layout placeholder: not a "
                         "Lichtblick web build (run scripts/lichtblick.sh)")
    data = json.dumps(json.loads(layout.read_text()))  # checked, on one line
    return html.replace(PLACEHOLDER, data).encode()


class Handler(SimpleHTTPRequestHandler):
    """Static files from the build; `/` and `/index.html` are the page with the layout."""

    extensions_map = {**SimpleHTTPRequestHandler.extensions_map,
                      ".wasm": "application/wasm", ".js": "text/javascript"}

    def __init__(self, *args: object, index: bytes, **kwargs: object) -> None:
        self.index = index
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]

    def do_GET(self) -> None:
        if self.path.split("?", 1)[0] in ("/", "/index.html"):
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(self.index)))
            self.end_headers()
            self.wfile.write(self.index)
            return
        super().do_GET()

    def log_message(self, format: str, *args: object) -> None:
        log.debug("%s " + format, self.address_string(), *args)


def server(web: Path, host: str = "127.0.0.1", port: int = 0,
           layout: Path = LAYOUT) -> ThreadingHTTPServer:
    """An HTTP server for the build in `web` (not yet serving); port 0 picks a free one."""
    handler = functools.partial(Handler, directory=str(web),
                                index=index_with_layout(web, layout))
    return ThreadingHTTPServer((host, port), handler)


@contextmanager
def serving(web: Path, layout: Path = LAYOUT) -> Iterator[str]:
    """The build served on 127.0.0.1 at a free port while the block runs: its base URL."""
    httpd = server(web, layout=layout)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}"
    finally:
        httpd.shutdown()
        httpd.server_close()
        thread.join(timeout=10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("web", type=Path, help="the web build (its index.html)")
    parser.add_argument("--listen", default="127.0.0.1:8080", help="HOST:PORT")
    parser.add_argument("--layout", type=Path, default=LAYOUT, help="a Lichtblick layout")
    parser.add_argument("--view", default="ws://127.0.0.1:8765",
                        help="the live view's address, for the URL printed")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    host, _, port = args.listen.rpartition(":")
    httpd = server(args.web, host, int(port), args.layout)
    log.info("Lichtblick at http://%s:%d/?ds=foxglove-websocket&ds.url=%s (Ctrl-C stops)",
             host, httpd.server_address[1], args.view)
    try:
        httpd.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        httpd.server_close()


if __name__ == "__main__":
    main()
