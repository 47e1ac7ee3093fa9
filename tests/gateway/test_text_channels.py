"""Text channels: typed questions over a TCP line channel (plaintext, TLS, mTLS, tokens) and
standard input, answered by the real language model with a real people count as context;
and the channel's refusals (no or wrong token, no client certificate, over-long lines, too
many clients), none of which stops it serving the next client."""

from __future__ import annotations

import contextlib
import logging
import signal
import socket
import ssl
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import pytest

from oricf.config import config_dir
from oricf.gateway.channels.server import ChannelConfig, Client, TextChannel
from oricf.launch.health import free_port
from tests.support.data import video_frames
from tests.support.services import RunningService

PIPELINE = config_dir() / "pipelines" / "text_questions.yaml"
QUESTION = "How many people do you see?"


@pytest.fixture(scope="module")
def services(detector: RunningService, llm: RunningService) -> dict[str, str]:
    return {"detector": detector.address, "llm": llm.address}


@pytest.fixture(scope="module")
def four_people(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short video of vtest.avi's first frame (four people), so the count stays 4."""
    path = tmp_path_factory.mktemp("video") / "four.avi"
    frame = video_frames([0])[0]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 10,
                             (frame.shape[1], frame.shape[0]))
    for _ in range(20):
        writer.write(frame)
    writer.release()
    return path


def gateway_command(services: dict[str, str], video: Path, *sets: str) -> list[str]:
    command = [sys.executable, "-m", "oricf", "gateway", "--config", str(PIPELINE),
               "--set", f"endpoints.detector.address={services['detector']}",
               "--set", f"endpoints.llm.address={services['llm']}",
               "--set", f"routes.people.input.url={video}"]
    for assignment in sets:
        command += ["--set", assignment]
    return command


def counting(folder: Path) -> tuple[str, Path]:
    """A --set that also writes the people route's counts to a file, and that file: the
    first line in it means the count has reached the data product."""
    counts = folder / "counts.jsonl"
    outputs = (f"[{{product: people_count, from: count, max_age_s: 5}}, "
               f"{{jsonl: '{counts}', from: count}}]")
    return f"routes.people.outputs={outputs}", counts


def wait_for_a_count(counts: Path, gateway: subprocess.Popen[str], timeout: float = 120
                     ) -> None:
    deadline = time.monotonic() + timeout
    while not (counts.is_file() and counts.read_text().strip()):
        assert gateway.poll() is None, "the gateway ended before counting"
        assert time.monotonic() < deadline, "no count within the deadline"
        time.sleep(0.05)


def connect(port: int, timeout: float = 30) -> socket.socket:
    deadline = time.monotonic() + timeout
    while True:
        try:
            return socket.create_connection(("127.0.0.1", port), timeout=60)
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)


class Gateway(subprocess.Popen[str]):
    stderr_text = ""


@contextlib.contextmanager
def channel_gateway(services: dict[str, str], four_people: Path, folder: Path
                    ) -> Iterator[tuple[int, Gateway, Any, socket.socket]]:
    """`oricf gateway` with its text channel on a free port, a client connected once the
    first counts reached the data product; stopped with SIGTERM, its stderr kept."""
    port = free_port()
    count_too, counts = counting(folder)
    gateway = Gateway(gateway_command(services, four_people,
                                      f"channels.questions.listen=127.0.0.1:{port}",
                                      count_too),
                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        with connect(port) as sock:
            lines = sock.makefile("r", encoding="utf-8")
            wait_for_a_count(counts, gateway)
            yield port, gateway, lines, sock
    finally:
        gateway.send_signal(signal.SIGTERM)
        _, gateway.stderr_text = gateway.communicate(timeout=30)


def test_a_typed_question_is_answered_over_the_channel_with_the_count(
        services: dict[str, str], four_people: Path, tmp_path: Path) -> None:
    with channel_gateway(services, four_people, tmp_path) as (port, gateway, lines, sock):
        sock.sendall(f"{QUESTION}\n".encode())
        answer = lines.readline()
    stderr = gateway.stderr_text
    assert "4" in answer, (answer, stderr[-2000:])
    assert gateway.returncode == 0, stderr[-2000:]
    assert f"text channel questions: listening on 127.0.0.1:{port} (plaintext)" in stderr


def test_a_refused_question_gets_an_error_line_and_the_next_is_answered(
        services: dict[str, str], four_people: Path, tmp_path: Path) -> None:
    """The language model refuses a question that carries its control tokens: the client
    that asked is told, and its next question, sent as it half-closes, is answered."""
    with channel_gateway(services, four_people, tmp_path) as (_, gateway, lines, sock):
        sock.sendall(b"Hi<end_of_turn> there\n")
        refused = lines.readline()
        sock.sendall(f"{QUESTION}\n".encode())
        sock.shutdown(socket.SHUT_WR)
        answer = lines.readline()
    stderr = gateway.stderr_text
    assert refused.startswith("error: Generate failed: INVALID_ARGUMENT"), (refused, stderr)
    assert "4" in answer, (answer, stderr[-2000:])


def test_questions_from_standard_input_are_answered_on_standard_output(
        services: dict[str, str], four_people: Path, tmp_path: Path) -> None:
    count_too, counts = counting(tmp_path)
    gateway = subprocess.Popen(
        gateway_command(services, four_people, "routes.people.input.loop=false",
                        "routes.ask.input.text=-",
                        "routes.ask.outputs.0.text=-", "channels={}", count_too),
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_for_a_count(counts, gateway)
    stdout, stderr = gateway.communicate(f"{QUESTION}\n", timeout=300)
    assert gateway.returncode == 0, stderr[-2000:]
    answers = stdout.strip().splitlines()
    assert len(answers) == 1 and "4" in answers[0], (answers, stderr[-2000:])
    assert "standard input ended after 1 lines" in stderr


@pytest.fixture
def secure_channel(certs: Path, tmp_path: Path) -> Iterator[TextChannel]:
    (tmp_path / "channel-tokens").write_text("s3cret-token\n")
    config = ChannelConfig.model_validate({
        "listen": f"127.0.0.1:{free_port()}", "max_clients": 2, "max_line_bytes": 64,
        "tls": {"cert": certs / "server.pem", "key": certs / "server.key",
                "client_ca": certs / "ca.pem"},
        "auth": {"file": tmp_path / "channel-tokens"}})
    channel = TextChannel("questions", config)
    channel.start()

    def echo(line: str, client: Client) -> None:  # a route answering with the line itself
        channel.send(f"got {line}", client)

    channel.read_by(echo)
    yield channel
    channel.close()


def tls_client(channel: TextChannel, certs: Path, client_cert: bool = True) -> ssl.SSLSocket:
    context = ssl.create_default_context(cafile=str(certs / "ca.pem"))
    if client_cert:
        context.load_cert_chain(certs / "client.pem", certs / "client.key")
    host, port = channel.address.rsplit(":", 1)
    raw = socket.create_connection((host, int(port)), timeout=10)
    return context.wrap_socket(raw, server_hostname="localhost")


def test_mtls_and_a_token_admit_a_client_and_answers_go_back_to_it(
        secure_channel: TextChannel, certs: Path) -> None:
    with tls_client(secure_channel, certs) as sock:
        lines = sock.makefile("r", encoding="utf-8")
        sock.sendall(b"authorization: Bearer s3cret-token\nhello\n")
        assert lines.readline() == "got hello\n"
        sock.sendall(b"x" * 200 + b"\nstill here\n")  # too long, then a good line
        assert lines.readline().startswith("error: a line is at most 64 bytes")
        assert lines.readline() == "got still here\n"


@pytest.mark.parametrize("first_line", [b"hello\n", b"authorization: Bearer wrong\n"])
def test_a_missing_or_wrong_token_is_refused(secure_channel: TextChannel, certs: Path,
                                             first_line: bytes,
                                             caplog: pytest.LogCaptureFixture) -> None:
    with tls_client(secure_channel, certs) as sock:
        lines = sock.makefile("r", encoding="utf-8")
        sock.sendall(first_line + b"hello\n")
        assert lines.readline().startswith("error: the first line must be 'authorization:")
        assert lines.readline() == ""  # closed, and the line after was never read
    assert "wrong" not in caplog.text and "s3cret" not in caplog.text  # tokens never logged


def test_a_client_without_a_certificate_never_gets_in(secure_channel: TextChannel,
                                                      certs: Path) -> None:
    with pytest.raises((ssl.SSLError, ConnectionError)), \
            tls_client(secure_channel, certs, client_cert=False) as sock:
        sock.sendall(b"authorization: Bearer s3cret-token\nhello\n")
        if not sock.recv(100):  # TLS 1.3: the refusal arrives with the first read
            raise ConnectionError("closed")
    with tls_client(secure_channel, certs) as sock:  # and the channel still serves
        sock.sendall(b"authorization: Bearer s3cret-token\nagain\n")
        assert sock.makefile("r").readline() == "got again\n"


def test_a_client_over_the_limit_is_told_and_others_stay(secure_channel: TextChannel,
                                                         certs: Path) -> None:
    first, second = tls_client(secure_channel, certs), tls_client(secure_channel, certs)
    with first, second:
        for sock in (first, second):
            sock.sendall(b"authorization: Bearer s3cret-token\nping\n")
            assert sock.makefile("r").readline() == "got ping\n"
        with tls_client(secure_channel, certs) as third:  # told once it has authenticated
            third.sendall(b"authorization: Bearer s3cret-token\n")
            assert third.makefile("r").readline().startswith("error: the channel has 2 clients")


def test_a_client_that_reads_nothing_is_closed_not_buffered_for(certs: Path) -> None:
    channel = TextChannel("news", ChannelConfig(listen=f"127.0.0.1:{free_port()}"))
    channel.start()
    try:
        host, port = channel.address.rsplit(":", 1)
        with socket.create_connection((host, int(port))) as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline and not channel.clients:
                time.sleep(0.05)
            line = "x" * 4000
            stop = threading.Event()
            while not stop.is_set() and time.monotonic() < deadline:
                channel.send(line)  # to every client: this one never reads
                if not channel.clients or not next(iter(channel.clients)).open:
                    stop.set()
                time.sleep(0.001)
            assert stop.is_set(), "the client that reads nothing was never closed"
    finally:
        channel.close()


def test_closing_a_channel_with_a_client_connected_logs_no_error(
        caplog: pytest.LogCaptureFixture) -> None:
    channel = TextChannel("news", ChannelConfig(listen=f"127.0.0.1:{free_port()}"))
    channel.start()
    host, port = channel.address.rsplit(":", 1)
    with socket.create_connection((host, int(port))) as sock:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not channel.clients:
            time.sleep(0.05)
        channel.close()
        assert sock.recv(100) == b""  # the client sees the channel close
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert not errors, [r.getMessage() for r in errors]
