"""The speech synthesis service behind mTLS and a bearer token, as compose/edge.yaml and the
robot deployment run it: a caller with the client certificate and the token is answered,
sentence by sentence too; one without the token is refused before any audio is made."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import grpc
import pytest

from oricf.tls import ClientTls
from oricf.v1 import synthesis_pb2, synthesis_pb2_grpc
from tests.support.certs import TOKEN
from tests.support.services import RunningService, running_service


@pytest.fixture(scope="module")
def secured(certs: Path) -> Iterator[RunningService]:
    server = {"tls": {"cert": str(certs / "server.pem"), "key": str(certs / "server.key"),
                      "client_ca": str(certs / "ca.pem")},
              "auth": {"file": str(certs / "tokens")}, "reflection": False}
    with running_service("tts", {"server": server}) as service:
        yield service


def stub(certs: Path, service: RunningService) -> tuple[grpc.Channel, Any]:
    tls = ClientTls(ca=certs / "ca.pem", cert=certs / "client.pem", key=certs / "client.key")
    channel = tls.channel(f"localhost:{service.host.port}", [])
    return channel, synthesis_pb2_grpc.SpeechSynthesizerStub(channel)


def test_the_token_holder_is_answered_and_others_are_refused(certs: Path,
                                                             secured: RunningService) -> None:
    channel, voice = stub(certs, secured)
    request = synthesis_pb2.SynthesizeRequest(text="Hello. I can see 2 people.")
    token = (("authorization", f"Bearer {TOKEN}"),)
    with channel:
        reply = voice.Synthesize(request, timeout=60, metadata=token)
        assert reply.duration_s > 1.0
        chunks = list(voice.SynthesizeStream(request, timeout=60, metadata=token))
        assert [c.sentence for c in chunks] == [0, 1]
        for metadata, code in [((), grpc.StatusCode.UNAUTHENTICATED),
                               ((("authorization", "Bearer wrong"),),
                                grpc.StatusCode.PERMISSION_DENIED)]:
            with pytest.raises(grpc.RpcError) as refused:
                voice.Synthesize(request, timeout=10, metadata=metadata)
            assert refused.value.code() == code
            with pytest.raises(grpc.RpcError) as refused:
                list(voice.SynthesizeStream(request, timeout=10, metadata=metadata))
            assert refused.value.code() == code


def test_plaintext_callers_get_nothing(secured: RunningService) -> None:
    with grpc.insecure_channel(secured.address) as channel, pytest.raises(grpc.RpcError):
        synthesis_pb2_grpc.SpeechSynthesizerStub(channel).Synthesize(
            synthesis_pb2.SynthesizeRequest(text="Hello."), timeout=5)
