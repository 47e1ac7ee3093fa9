"""Hostile clients of the Lichtblick app server (scripts/lichtblick_serve.py), against a
stand-in web build (an index.html with the layout placeholder, a script, a folder, links in
and out of the folder): where it listens (a bare port is loopback; beyond loopback only
with TLS; IPv6 loopback), traversal and links out of the folder, folder listings, NUL and
fuzzed paths, half-sent requests by the hundred. Every answer is the file asked for or a
client error, nothing outside the folder is ever served, and a browser is served
meanwhile."""

from __future__ import annotations

import ssl
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from types import ModuleType
from urllib.parse import quote

import httpx
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from oricf.hosts import Address
from oricf.http_connections import MIN_IDLE_S
from tests.support.fuzzing import examples
from tests.support.processes import free_port
from tests.support.scripts import SCRIPTS, load_script
from tests.support.sockets import TCP_LISTEN, inet_sockets, peer_closed
from tests.support.waiting import wait_for

PAGE = "<html><script>const layout = /*LICHTBLICK_SUITE_DEFAULT_LAYOUT_PLACEHOLDER*/;</script>"
SCRIPT = b"console.log('the app');\n"
HALF_HEADERS = b"GET / HTTP/1.1\r\nHost: x\r\n"  # the headers never end
HALF_SENT = 200
# The threads a few hundred connections may cost at most (the old server: one each).
THREADS_ALLOWED = 20


@pytest.fixture(scope="module")
def serve() -> ModuleType:
    return load_script("lichtblick_serve")


@pytest.fixture(scope="module")
def web(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A stand-in build: index.html, app.js, a folder, a link to app.js inside it, links to
    /etc and /etc/passwd."""
    web = tmp_path_factory.mktemp("web")
    (web / "index.html").write_text(PAGE)
    (web / "app.js").write_bytes(SCRIPT)
    (web / "static").mkdir()
    (web / "static" / "panel.wasm").write_bytes(b"\0asm")
    (web / "inside.js").symlink_to(web / "app.js")
    (web / "etc").symlink_to("/etc")
    (web / "passwd").symlink_to("/etc/passwd")
    return web


@pytest.fixture(scope="module")
def port(serve: ModuleType, web: Path) -> Iterator[int]:
    with serve.serving(web) as base:
        yield int(base.rsplit(":", 1)[1])


def get(port: int, target: bytes, host: str = "127.0.0.1") -> tuple[int, bytes, bytes]:
    """A GET of `target` as sent, unnormalised: (status, headers, body)."""
    import socket

    with socket.create_connection((host, port), timeout=15) as sock:
        sock.sendall(b"GET " + target + b" HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
        answer = b""
        while chunk := sock.recv(65536):
            answer += chunk
    assert answer, f"no answer to GET {target!r}"
    head, _, body = answer.partition(b"\r\n\r\n")
    return int(head.split(b" ", 2)[1]), head.lower(), body


def test_the_page_carries_the_layout_and_the_files_are_served(port: int) -> None:
    for target in (b"/", b"/index.html"):
        status, head, body = get(port, target)
        assert status == 200 and b"text/html" in head
        assert b"LICHTBLICK_SUITE_DEFAULT_LAYOUT_PLACEHOLDER" not in body
        assert b"const layout = {" in body
    assert get(port, b"/app.js")[::2] == (200, SCRIPT)
    assert get(port, b"/inside.js")[::2] == (200, SCRIPT)  # a link inside the folder
    status, head, _ = get(port, b"/static/panel.wasm")
    assert status == 200 and b"content-type: application/wasm" in head


ESCAPES = [b"/etc/passwd", b"/passwd", b"/etc/hostname", b"/../../../../etc/passwd",
           b"/static/../../../../etc/passwd", b"/%2e%2e/%2e%2e/%2e%2e/etc/passwd",
           b"/static/..%2f..%2f..%2f..%2fetc%2fpasswd", b"//etc/passwd", b"/etc%2fpasswd",
           b"/./etc/./passwd", b"/static/%2e%2e/passwd", b"/%5c..%5c..%5cetc%5cpasswd"]


@pytest.mark.parametrize("target", ESCAPES, ids=[t.decode() for t in ESCAPES])
def test_nothing_outside_the_folder_is_served(port: int, target: bytes) -> None:
    status, _, body = get(port, target)
    assert status == 404
    assert b"root:" not in body


@pytest.mark.parametrize("target", [b"/static/", b"/static", b"/etc/", b"/etc", b"/."])
def test_no_folder_is_listed(port: int, target: bytes) -> None:
    status, _, body = get(port, target)
    assert status == 404
    assert b"panel.wasm" not in body and b"passwd" not in body


@pytest.mark.parametrize("target", [b"/%00", b"/app.js%00.html", b"/static/%00/x",
                                    b"/etc/passwd%00"])
def test_a_nul_in_the_path_is_400(port: int, target: bytes) -> None:
    status, _, body = get(port, target)
    assert status == 400 and b"NUL" in body
    assert get(port, b"/app.js")[0] == 200  # and the server goes on


@settings(max_examples=examples(150), deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(path=st.one_of(st.text(max_size=60), st.binary(max_size=60),
                      st.lists(st.sampled_from(["..", ".", "etc", "passwd", "static", "",
                                                "\0", "%2e%2e", "inside.js"]), max_size=8)
                      .map("/".join)))
def test_fuzzed_paths_get_a_file_or_a_client_error(port: int, path: str | bytes) -> None:
    status, _, body = get(port, b"/" + quote(path, safe="/%").encode())
    assert status in (200, 400, 404)
    assert b"root:" not in body


def test_half_sent_requests_hold_no_thread_and_lock_no_browser_out(port: int) -> None:
    """More connections than the limit send headers that never end: no thread each, and
    once they have waited MIN_IDLE_S a browser's requests are answered (the oldest
    closed to make room)."""
    import socket

    threads = threading.active_count()
    with ExitStack() as stack:
        half = [stack.enter_context(socket.create_connection(("127.0.0.1", port), timeout=15))
                for _ in range(HALF_SENT)]
        for sock in half:
            sock.sendall(HALF_HEADERS)
        time.sleep(2 * MIN_IDLE_S)  # the age a connection needs before it may go for room
        assert threading.active_count() - threads < THREADS_ALLOWED
        for _ in range(3):
            assert get(port, b"/")[0] == 200


def test_a_request_whose_headers_never_end_is_cut_off(
        serve: ModuleType, web: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import socket

    monkeypatch.setattr(serve, "HEADER_TIMEOUT_S", 1.0)
    with serve.serving(web) as base, socket.create_connection(
            ("127.0.0.1", int(base.rsplit(":", 1)[1])), timeout=15) as sock:
        sock.sendall(HALF_HEADERS)
        wait_for(lambda: peer_closed(sock), 15, "the half-sent request closed")


@contextmanager
def script(web: Path, listen: str, *flags: str) -> Iterator[subprocess.Popen[str]]:
    """`python scripts/lichtblick_serve.py WEB --listen LISTEN FLAGS` as its own process."""
    process = subprocess.Popen([sys.executable, str(SCRIPTS / "lichtblick_serve.py"), str(web),
                                "--listen", listen, *flags], stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    try:
        yield process
    finally:
        process.kill()
        process.wait(timeout=10)
        assert process.stdout is not None
        process.stdout.close()


@pytest.mark.parametrize(("listen", "host"), [("PORT", "127.0.0.1"), (":PORT", "127.0.0.1"),
                                              ("[::1]:PORT", "::1")])
def test_a_bare_port_listens_on_loopback_and_ipv6_loopback_is_taken(
        web: Path, listen: str, host: str) -> None:
    port = free_port()
    with script(web, listen.replace("PORT", str(port))) as process:
        def listening() -> list[str]:
            assert process.poll() is None, process.stdout.read() if process.stdout else ""
            return [str(s.address) for s in inet_sockets(process.pid)
                    if s.port == port and s.state == TCP_LISTEN]

        wait_for(listening, 60, "the server listening")
        assert listening() == [host]
        assert get(port, b"/", host)[0] == 200
        assert f"Lichtblick at http://{Address(host, port)}/" in _first_line(process)


def _first_line(process: subprocess.Popen[str]) -> str:
    assert process.stdout is not None
    return process.stdout.readline()


@pytest.mark.parametrize("listen", ["0.0.0.0:PORT", "[::]:PORT", "example.org:PORT"])
def test_beyond_loopback_without_tls_is_refused_naming_the_flags(web: Path,
                                                                 listen: str) -> None:
    port = free_port()
    with script(web, listen.replace("PORT", str(port))) as process:
        assert process.wait(timeout=60) == 2
        assert process.stdout is not None
        said = process.stdout.read()
    assert "reachable from other machines" in said and "--tls-cert and --tls-key" in said
    assert "Traceback" not in said


def test_beyond_loopback_with_tls_is_served_over_https(web: Path, certs: Path) -> None:
    port = free_port()
    with script(web, f"0.0.0.0:{port}", "--tls-cert", str(certs / "server.pem"),
                "--tls-key", str(certs / "server.key")) as process:
        assert f"Lichtblick at https://0.0.0.0:{port}/" in _first_line(process)
        context = ssl.create_default_context(cafile=certs / "ca.pem")
        with httpx.Client(verify=context) as client:
            answer = client.get(f"https://127.0.0.1:{port}/app.js", timeout=15)
        assert (answer.status_code, answer.content) == (200, SCRIPT)


def test_a_key_that_cannot_be_loaded_is_named(web: Path, certs: Path, tmp_path: Path) -> None:
    key = tmp_path / "server.key"
    key.write_text("not a key\n")
    key.chmod(0o600)
    with script(web, "127.0.0.1:0", "--tls-cert", str(certs / "server.pem"),
                "--tls-key", str(key)) as process:
        assert process.wait(timeout=60) == 2
        assert process.stdout is not None
        said = process.stdout.read()
    assert str(key) in said and "Traceback" not in said
