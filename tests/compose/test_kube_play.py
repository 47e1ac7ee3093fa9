"""The rendered Kubernetes manifests run on podman (compose/kubernetes/play.sh: `podman kube
play` of their Deployments, ConfigMaps and Secret, from the image compose/stack.sh builds),
in the engines suite (`-m engines`, docs/testing.md). Each pod comes up SERVING on its
plaintext probe port, refuses plaintext on its own port, answers there over mTLS only with
the token, and answers correctly; a gateway outside the pods counts the people of a video
through the detector's pod, resolving it as a cluster client would, by the Service's name
in its certificate."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import grpc
import pytest
import yaml
from google.protobuf import json_format
from grpc_health.v1 import health_pb2, health_pb2_grpc

from oricf.config import REPO_ROOT, config_dir
from oricf.launch.certs import make_certificates
from oricf.tls import ClientTls
from oricf.v1 import (
    detector_pb2,
    detector_pb2_grpc,
    language_pb2,
    language_pb2_grpc,
    policy_pb2,
    policy_pb2_grpc,
    speech_pb2,
    speech_pb2_grpc,
    synthesis_pb2,
    synthesis_pb2_grpc,
)
from tests.compose.smoke import smoke_check
from tests.support.data import video_path

pytestmark = pytest.mark.engines

PLAY = REPO_ROOT / "compose" / "kubernetes" / "play.sh"
PORTS = {"detector": 50051, "asr": 50052, "llm": 50053, "tts": 50054, "policy": 50055}
HOSTS = [f"{name}.oricf.svc.cluster.local" for name in PORTS]
HEALTH_PORT = 50050
CALLS: dict[str, tuple[Any, str, Any]] = {
    "detector": (detector_pb2_grpc.DetectorStub, "Detect", detector_pb2.DetectRequest),
    "asr": (speech_pb2_grpc.SpeechRecognizerStub, "Transcribe", speech_pb2.TranscribeRequest),
    "llm": (language_pb2_grpc.LanguageModelStub, "Generate", language_pb2.GenerateRequest),
    "tts": (synthesis_pb2_grpc.SpeechSynthesizerStub, "Synthesize",
            synthesis_pb2.SynthesizeRequest),
    "policy": (policy_pb2_grpc.PolicyStub, "Act", policy_pb2.Observation),
}


@dataclass
class Played:
    certs: Path
    addresses: dict[str, str]   # service -> the pod's IP address
    up: str                     # what `play.sh up` printed

    def tls(self, service: str) -> ClientTls:
        """The client certificate, checking the server's against the Service's name."""
        return ClientTls(ca=self.certs / "ca.pem", cert=self.certs / "client.pem",
                         key=self.certs / "client.key",
                         server_name=f"{service}.oricf.svc.cluster.local")

    @property
    def token(self) -> tuple[tuple[str, str]]:
        return (("authorization", f"Bearer {(self.certs / 'tokens').read_text().strip()}"),)


def play(*args: str, env: dict[str, str], timeout: float) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(PLAY), *args], cwd=REPO_ROOT, capture_output=True, text=True,
                          timeout=timeout, check=False, env={**os.environ, **env})


def pod_address(pod: str) -> str:
    infra = subprocess.run(["podman", "pod", "inspect", "-f", "{{.InfraContainerID}}", pod],
                           capture_output=True, text=True, check=True).stdout.strip()
    return subprocess.run(
        ["podman", "inspect", "-f", "{{range .NetworkSettings.Networks}}{{.IPAddress}}{{end}}",
         infra], capture_output=True, text=True, check=True).stdout.strip()


@pytest.fixture(scope="module")
def played(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Played]:
    engine = {**os.environ, "ORICF_ENGINE": "podman"}
    if subprocess.run(["podman", "image", "exists", "oricf:local"], check=False).returncode:
        build = subprocess.run([str(REPO_ROOT / "compose" / "stack.sh"), "build", "detector"],
                               cwd=REPO_ROOT, capture_output=True, text=True, timeout=1500,
                               env=engine, check=False)
        assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    certs = tmp_path_factory.mktemp("kubernetes-certs")
    make_certificates(certs, HOSTS)
    env = {"ORICF_KUBE_CERTS": str(certs), "ORICF_WAIT_TIMEOUT": "600"}
    up = play("up", *PORTS, env=env, timeout=900)
    try:
        assert up.returncode == 0, up.stdout[-3000:] + up.stderr[-3000:]
        yield Played(certs, {name: pod_address(f"{name}-pod-0") for name in PORTS}, up.stdout)
    finally:
        down = play("down", env=env, timeout=300)
        assert down.returncode == 0, down.stdout + down.stderr
        assert "down, no pod left" in down.stdout


def health(channel: grpc.Channel) -> int:
    stub = health_pb2_grpc.HealthStub(channel)
    return int(stub.Check(health_pb2.HealthCheckRequest(), timeout=5).status)


def test_only_what_podman_runs_is_played_and_the_rest_is_named(played: Played) -> None:
    rendered = play("render", env={"ORICF_KUBE_CERTS": str(played.certs)}, timeout=120)
    assert rendered.returncode == 0, rendered.stderr
    kinds = {doc["kind"] for doc in yaml.safe_load_all(rendered.stdout)}
    assert kinds <= {"Deployment", "ConfigMap", "Secret"} and "Deployment" in kinds
    for left in ("Namespace/oricf", "Service/detector", "HorizontalPodAutoscaler/detector",
                 "NetworkPolicy/oricf-services"):
        assert left in rendered.stderr


@pytest.mark.parametrize("service", list(PORTS))
def test_the_pod_serves_its_probe_port_and_answers_over_mtls_with_the_token(
        played: Played, service: str) -> None:
    address = played.addresses[service]
    assert f"{service}-pod-0 SERVING after" in played.up
    with grpc.insecure_channel(f"{address}:{HEALTH_PORT}") as probe:   # the kubelet's probe
        assert health(probe) == health_pb2.HealthCheckResponse.SERVING
    own = f"{address}:{PORTS[service]}"
    with grpc.insecure_channel(own) as plaintext, pytest.raises(grpc.RpcError):
        health(plaintext)
    check = smoke_check()
    stub_class, method, request_class = CALLS[service]
    request = json_format.ParseDict(check.REQUESTS[service](), request_class())
    with played.tls(service).channel(own, []) as channel:
        call = getattr(stub_class(channel), method)
        with pytest.raises(grpc.RpcError) as refused:
            call(request, timeout=10)
        assert refused.value.code() == grpc.StatusCode.UNAUTHENTICATED
        reply = call(request, timeout=120, metadata=played.token)
    answer = json_format.MessageToDict(reply, preserving_proto_field_name=True)
    assert check.CHECKS[service](answer) is None, answer


def test_the_gateway_counts_people_through_the_detector_pod(played: Played,
                                                            tmp_path: Path) -> None:
    overlay = tmp_path / "pod.yaml"
    overlay.write_text(yaml.safe_dump({
        "endpoints": {"detector": {
            "address": f"ipv4:{played.addresses['detector']}:{PORTS['detector']}",
            "tls": {"ca": str(played.certs / "ca.pem"), "cert": str(played.certs / "client.pem"),
                    "key": str(played.certs / "client.key"),
                    "server_name": "detector.oricf.svc.cluster.local"},
            "token": {"file": str(played.certs / "tokens")}}},
        "routes": {"people": {"input": {"url": str(video_path()), "fps": 100}}}}))
    result = subprocess.run(
        [sys.executable, "-m", "oricf", "gateway",
         "--config", str(config_dir() / "pipelines" / "people_video.yaml"),
         "--overlay", str(overlay)], capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stderr[-3000:]
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    assert len(lines) >= 20, result.stderr[-3000:]
    assert all(line["route"] == "people" and 1 <= line["count"] <= 15 for line in lines)
    assert "vtest.avi ended after 795 frames" in result.stderr
