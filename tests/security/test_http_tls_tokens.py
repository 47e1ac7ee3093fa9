"""The HTTP side (OpenAI-compatible API) under the service's own TLS, mTLS and bearer tokens:
a real `oricf serve asr --tls-cert --tls-key --tls-client-ca --auth-token-file
--http-listen` process, the official openai client over httpx with the client
certificate."""

from __future__ import annotations

import ssl
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import openai
import pytest

from oricf.audio import encode_wav
from oricf.launch.certs import make_certificates
from oricf.launch.health import wait_serving
from oricf.tls import ClientTls
from tests.support.certs import TOKEN
from tests.support.openai_http import HttpService, client, http_service
from tests.support.speech import QUESTION, QUESTION_WORDS, speech, words

MODEL = "whisper-tiny-en"


@pytest.fixture(scope="module")
def secured(certs: Path) -> Iterator[HttpService]:
    tls = ClientTls(ca=certs / "ca.pem", cert=certs / "client.pem", key=certs / "client.key")

    def ready(address: str, process: subprocess.Popen[str]) -> None:
        wait_serving(address, timeout=120, process=process, tls=tls)

    with http_service("asr", "--tls-cert", str(certs / "server.pem"),
                      "--tls-key", str(certs / "server.key"),
                      "--tls-client-ca", str(certs / "ca.pem"),
                      "--auth-token-file", str(certs / "tokens"), "--no-reflection",
                      scheme="https", grpc_ready=ready) as service:
        yield service


def tls_context(certs: Path, with_cert: bool = True) -> ssl.SSLContext:
    context = ssl.create_default_context(cafile=str(certs / "ca.pem"))
    if with_cert:
        context.load_cert_chain(certs / "client.pem", certs / "client.key")
    return context


def api(service: HttpService, certs: Path, token: str, **options: Any) -> openai.OpenAI:
    http = httpx.Client(verify=tls_context(certs, **options), timeout=30)
    return client(service, api_key=token, http_client=http)


def transcribe(api: openai.OpenAI) -> str:
    wav = encode_wav(speech(QUESTION), 16000)
    return api.audio.transcriptions.create(model=MODEL, file=("q.wav", wav)).text


def test_mtls_and_a_token_are_both_required(secured: HttpService, certs: Path) -> None:
    assert words(transcribe(api(secured, certs, TOKEN))) == list(QUESTION_WORDS)
    for token in ("guess", TOKEN + "x"):
        with pytest.raises(openai.AuthenticationError) as refused:
            transcribe(api(secured, certs, token))
        assert refused.value.status_code == 401
    plain = HttpService(secured.process, "", secured.base_url.replace("https", "http"))
    with pytest.raises(openai.APIConnectionError):
        transcribe(client(plain, api_key=TOKEN))
    with pytest.raises(openai.APIConnectionError):  # no client certificate
        transcribe(api(secured, certs, TOKEN, with_cert=False))


def test_health_needs_no_token_but_tls(secured: HttpService, certs: Path) -> None:
    response = httpx.get(f"{secured.base_url}/health", verify=tls_context(certs), timeout=10)
    assert response.status_code == 200 and response.json() == {"status": "SERVING"}
    models = httpx.get(f"{secured.base_url}/v1/models", verify=tls_context(certs), timeout=10)
    assert models.status_code == 401
    assert models.json()["error"]["code"] == "missing_api_key"


def test_a_certificate_from_another_ca_is_refused(secured: HttpService, certs: Path,
                                                  tmp_path: Path) -> None:
    make_certificates(tmp_path, ["localhost"])
    context = ssl.create_default_context(cafile=str(certs / "ca.pem"))
    context.load_cert_chain(tmp_path / "client.pem", tmp_path / "client.key")
    with pytest.raises(httpx.TransportError):
        httpx.get(f"{secured.base_url}/health", verify=context, timeout=10)


def test_tokens_never_reach_the_log(secured: HttpService, certs: Path) -> None:
    silence = encode_wav(np.zeros(16000, dtype=np.int16), 16000)
    api(secured, certs, TOKEN).audio.transcriptions.create(model=MODEL, file=("s.wav", silence))
    with pytest.raises(openai.AuthenticationError):
        api(secured, certs, "guess-" + TOKEN[:8]).models.list()
    secured.process.terminate()
    output, _ = secured.process.communicate(timeout=30)
    assert secured.process.returncode == 0
    assert "OpenAI-compatible HTTP API on port" in output and "mTLS" in output
    assert TOKEN not in output and "guess-" not in output
