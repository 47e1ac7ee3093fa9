"""TLS, mTLS and bearer tokens end to end: certificates from `oricf certs`, a real detector
requiring both, the gateway's endpoint presenting them, the health probe, `oricf serve`."""

from __future__ import annotations

import logging
import os
import stat
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import grpc
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection_pb2, reflection_pb2_grpc

from oricf.errors import ConfigError
from oricf.gateway.values import Frame
from oricf.launch.certs import make_certificates
from oricf.launch.health import status
from oricf.tls import ClientTls, ServerTls, TokenSource
from oricf.v1 import detector_pb2, detector_pb2_grpc
from tests.gateway.test_pipeline import FRAMES, pipeline_config, run_frames
from tests.support.certs import TOKEN
from tests.support.data import video_frames
from tests.support.detections import count
from tests.support.processes import free_port, oricf_process, wait_serving
from tests.support.services import RunningService, running_service


@pytest.fixture(scope="module")
def secured(certs: Path) -> Iterator[RunningService]:
    server = {"tls": {"cert": str(certs / "server.pem"), "key": str(certs / "server.key"),
                      "client_ca": str(certs / "ca.pem")},
              "auth": {"file": str(certs / "tokens")}, "reflection": False}
    with running_service("detector", {"server": server}) as service:
        yield service


def client_tls(certs: Path, with_cert: bool = True) -> ClientTls:
    if not with_cert:
        return ClientTls(ca=certs / "ca.pem")
    return ClientTls(ca=certs / "ca.pem", cert=certs / "client.pem", key=certs / "client.key")


def request() -> detector_pb2.DetectRequest:
    return detector_pb2.DetectRequest(image=Frame.from_pixels(video_frames([0])[0]).to_proto(),
                                      labels=["person"])


def detect(channel: grpc.Channel, token: str | None) -> detector_pb2.DetectResponse:
    metadata = (("authorization", f"Bearer {token}"),) if token is not None else ()
    return detector_pb2_grpc.DetectorStub(channel).Detect(request(), timeout=10,
                                                          metadata=metadata)


def code_of(channel: grpc.Channel, token: str | None) -> grpc.StatusCode:
    with pytest.raises(grpc.RpcError) as error:
        detect(channel, token)
    return error.value.code()


def test_certs_are_written_with_private_keys_private(certs: Path) -> None:
    for name in ("ca.pem", "server.pem", "client.pem"):
        assert (certs / name).read_text().startswith("-----BEGIN CERTIFICATE-----")
    for name in ("ca.key", "server.key", "client.key"):
        assert stat.S_IMODE(os.stat(certs / name).st_mode) == 0o600


def test_oricf_certs_writes_a_random_private_token(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "oricf", "certs", str(tmp_path / "c"),
                             "--host", "edge.local"], capture_output=True, text=True,
                            timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    token = (tmp_path / "c" / "tokens").read_text().strip()
    assert len(token) >= 40 and token not in result.stdout
    assert stat.S_IMODE(os.stat(tmp_path / "c" / "tokens").st_mode) == 0o600


def test_mtls_and_a_token_are_both_required(secured: RunningService, certs: Path,
                                            caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG)
    address = secured.address
    with grpc.insecure_channel(address) as plain:
        assert code_of(plain, TOKEN) == grpc.StatusCode.UNAVAILABLE
    with client_tls(certs, with_cert=False).channel(address, []) as no_cert:
        assert code_of(no_cert, TOKEN) == grpc.StatusCode.UNAVAILABLE
    with client_tls(certs).channel(address, []) as mtls:
        assert code_of(mtls, None) == grpc.StatusCode.UNAUTHENTICATED
        assert code_of(mtls, "guess") == grpc.StatusCode.PERMISSION_DENIED
        assert count(detect(mtls, TOKEN), "person") == 4
        health = health_pb2_grpc.HealthStub(mtls).Check(health_pb2.HealthCheckRequest(),
                                                        timeout=5)
        assert health.status == health_pb2.HealthCheckResponse.SERVING  # no token needed
        reflection = reflection_pb2_grpc.ServerReflectionStub(mtls)
        with pytest.raises(grpc.RpcError) as error:
            list(reflection.ServerReflectionInfo(iter([reflection_pb2.ServerReflectionRequest(
                list_services="")]), timeout=5, metadata=(("authorization", f"Bearer {TOKEN}"),)))
        assert error.value.code() == grpc.StatusCode.UNIMPLEMENTED  # reflection switched off
    assert TOKEN not in caplog.text and "guess" not in caplog.text


def test_a_certificate_from_another_ca_is_refused(secured: RunningService, certs: Path,
                                                  tmp_path: Path) -> None:
    make_certificates(tmp_path, ["localhost"])
    impostor = ClientTls(ca=certs / "ca.pem", cert=tmp_path / "client.pem",
                         key=tmp_path / "client.key")
    with impostor.channel(secured.address, []) as channel:
        assert code_of(channel, TOKEN) == grpc.StatusCode.UNAVAILABLE
    # and the gateway refuses a server whose certificate its CA did not sign
    with ClientTls(ca=tmp_path / "ca.pem", cert=certs / "client.pem",
                   key=certs / "client.key").channel(secured.address, []) as channel:
        assert code_of(channel, TOKEN) == grpc.StatusCode.UNAVAILABLE


def test_the_health_probe_speaks_tls(secured: RunningService, certs: Path) -> None:
    assert status(secured.address, tls=client_tls(certs)) == "SERVING"
    assert status(secured.address) == "UNREACHABLE"


def test_the_gateway_counts_people_over_mtls_with_a_token(secured: RunningService,
                                                          certs: Path) -> None:
    endpoint = {"tls": {"ca": str(certs / "ca.pem"), "cert": str(certs / "client.pem"),
                        "key": str(certs / "client.key"), "server_name": "localhost"},
                "token": {"file": str(certs / "tokens")}}
    # the first token in the file is sent; the service accepts every token in its file
    pipeline, outputs = run_frames(
        pipeline_config(secured.address, {"endpoints": {"detector": endpoint}}), FRAMES)
    assert next(v for t, v in outputs.sent if t == "/human_counter") == 4
    assert pipeline.routes["people"].stats.ok == len(FRAMES)
    without = {"endpoints": {"detector": {"tls": endpoint["tls"]}}}
    pipeline, outputs = run_frames(pipeline_config(secured.address, without), FRAMES[:1])
    assert outputs.sent == [] and pipeline.routes["people"].stats.errors == {"UNAUTHENTICATED": 1}


def test_oricf_serve_flags_and_the_health_command(certs: Path) -> None:
    port = free_port()
    address = f"127.0.0.1:{port}"
    tls = ["--tls-ca", str(certs / "ca.pem"), "--tls-cert", str(certs / "client.pem"),
           "--tls-key", str(certs / "client.key")]
    with oricf_process("serve", "detector", "--listen", address, "--tls-cert",
                       str(certs / "server.pem"), "--tls-key", str(certs / "server.key"),
                       "--tls-client-ca", str(certs / "ca.pem"), "--auth-token-file",
                       str(certs / "tokens")) as process:
        wait_serving(address, process=process, tls=client_tls(certs))
        probe = subprocess.run([sys.executable, "-m", "oricf.launch.health", address, *tls],
                               capture_output=True, text=True, timeout=30, check=False)
        plain = subprocess.run([sys.executable, "-m", "oricf.launch.health", address],
                               capture_output=True, text=True, timeout=30, check=False)
        process.terminate()
        output = process.communicate(timeout=30)[0]
    assert probe.returncode == 0 and "SERVING" in probe.stdout
    assert plain.returncode == 1
    assert "mTLS, bearer tokens" in output and TOKEN not in output


# Token files that cannot be used, each refused naming the file and the line, never quoting
# what the file holds: a token that gRPC metadata or an HTTP header cannot carry would
# otherwise fail every call (INTERNAL "Invalid metadata") or end in a UnicodeEncodeError.
BAD_TOKENS: dict[str, tuple[bytes, str]] = {
    "not latin-1": ("Sek€et-1\n".encode(), "line 1, character 4: a token is visible ASCII"),
    "latin-1": ("Sekret-ok\nSek\xe9et\n".encode("latin-1"), "line 2, character 4"),
    "a control character": (b"Sek\x01et\n", "line 1, character 4"),
    "a space inside": (b"Sek et\n", "line 1, character 4"),
    "a NUL": (b"Sekret\x00\n", "line 1, character 7"),
    "empty": (b"", "no token (one a line)"),
    "blank lines only": (b"\n  \n\t\n", "no token (one a line)"),
}


def token_file(folder: Path, data: bytes, mode: int = 0o600) -> Path:
    path = folder / "tokens"
    path.write_bytes(data)
    path.chmod(mode)
    return path


@pytest.mark.parametrize("case", BAD_TOKENS)
def test_a_token_that_cannot_be_sent_is_refused_naming_the_line(case: str,
                                                                tmp_path: Path) -> None:
    data, reason = BAD_TOKENS[case]
    path = token_file(tmp_path, data)
    with pytest.raises(ConfigError) as error:
        TokenSource(file=path).tokens()
    assert str(error.value).startswith(f"{path}: ") and reason in str(error.value)
    assert "Sek" not in str(error.value)  # what the file holds is not quoted


def test_token_variables_unset_empty_or_not_ascii_are_refused(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ORICF_TEST_TOKEN", raising=False)
    with pytest.raises(ConfigError, match=r"^\$ORICF_TEST_TOKEN: not set$"):
        TokenSource(env="ORICF_TEST_TOKEN").tokens()
    for value, reason in [("", "no token"), ("  ", "no token"), ("tök", "character 2")]:
        monkeypatch.setenv("ORICF_TEST_TOKEN", value)
        with pytest.raises(ConfigError, match=rf"^\$ORICF_TEST_TOKEN: .*{reason}"):
            TokenSource(env="ORICF_TEST_TOKEN").tokens()
    monkeypatch.setenv("ORICF_TEST_TOKEN", "  first!~token \n\nsecond\n")
    assert TokenSource(env="ORICF_TEST_TOKEN").tokens() == ["first!~token", "second"]


@pytest.mark.parametrize("mode", [0o666, 0o620, 0o602, 0o660])
def test_a_token_file_others_may_write_is_refused(mode: int, tmp_path: Path) -> None:
    path = token_file(tmp_path, f"{TOKEN}\n".encode(), mode)
    with pytest.raises(ConfigError, match=rf"^{path}: writable by .* \(mode 0{mode:o}\)"):
        TokenSource(file=path).tokens()


def test_a_token_file_every_user_may_read_is_taken_with_a_warning(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = token_file(tmp_path, f"{TOKEN}\n".encode(), 0o644)
    with caplog.at_level(logging.WARNING, logger="oricf.tls"):
        assert TokenSource(file=path).tokens() == [TOKEN]
    assert f"{path}: readable by every user of this machine (mode 0644)" in caplog.text
    assert TOKEN not in caplog.text
    caplog.clear()
    (tmp_path / "private").mkdir()
    private = token_file(tmp_path / "private", f"{TOKEN}\n".encode(), 0o640)
    with caplog.at_level(logging.WARNING, logger="oricf.tls"):
        assert TokenSource(file=private).tokens() == [TOKEN]
    assert not caplog.records


def test_token_files_and_keys_that_are_no_regular_file_are_not_read(tmp_path: Path) -> None:
    """/dev/zero once grew to gigabytes, a FIFO waited for a writer for ever, a 64 MB file
    was read whole: each is refused at once, before any read."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo, 0o600)
    big = token_file(tmp_path, b"")
    os.truncate(big, 64 << 20)
    cases = {Path("/dev/zero"): "a device, not a token file",
             fifo: r"a FIFO \(named pipe\), not a token file",
             tmp_path: "a folder, not a token file",
             big: "larger than 1,048,576 bytes",
             tmp_path / "missing": "file not found"}
    for path, reason in cases.items():
        with pytest.raises(ConfigError, match=f"^{path}: {reason}"):
            TokenSource(file=path).tokens()
    tls = ServerTls(cert=tmp_path / "missing", key=fifo)
    with pytest.raises(ConfigError, match=rf"^foxglove.tls.key: {fifo}: a FIFO"):
        tls.ssl_context("foxglove.tls")
    with pytest.raises(ConfigError, match=rf"^tls.ca: {fifo}: a FIFO"):
        ClientTls(ca=fifo).channel("127.0.0.1:1", [])
