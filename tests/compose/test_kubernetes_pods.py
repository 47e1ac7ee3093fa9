"""Each pod compose/kubernetes/ describes, run as the kubelet would run it but as a process
here: its ConfigMaps and Secret written where its volumes mount them (under a temporary
root instead of /), its container's arguments as rendered, KServe's {{.Name}} filled in. The
service must come up SERVING on the plaintext health port its probes ask, and answer on its
own port only with the client certificate (mTLS) and the token: the detector and the
policy answer correctly, the policy with the Hopper model its models volume declares."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import grpc
import pytest
from google.protobuf import json_format
from grpc_health.v1 import health_pb2, health_pb2_grpc

from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.tls import ClientTls
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc, policy_pb2, policy_pb2_grpc
from tests.compose.kubernetes import Document, by_kind, file_contents, render, workspace
from tests.compose.smoke import smoke_check
from tests.support.data import image
from tests.support.detections import count
from tests.support.processes import free_port, oricf_process, wait_serving

PODS = ["detector", "asr", "llm", "tts", "policy", "oricf-models/yolox-nano"]


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Document]]:
    kubernetes = workspace(tmp_path_factory.mktemp("kubernetes"))
    return kubernetes, render(kubernetes, "kserve")


def pod_of(documents: list[Document], pod: str) -> tuple[dict[str, Any], str]:
    """The pod spec, and the InferenceService's name for a runtime's {{.Name}}."""
    runtime, _, isvc = pod.partition("/")
    if isvc:
        return by_kind(documents, "ServingRuntime")[runtime]["spec"], isvc
    return by_kind(documents, "Deployment")[pod]["spec"]["template"]["spec"], ""


class Root:
    """The pod's file system under a folder, and the addresses it listens on moved to free
    local ports."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.ports: dict[str, str] = {}

    def rewrite(self, text: str) -> str:
        text = text.replace("/etc/oricf/", f"{self.folder}/etc/oricf/")
        for listen, local in self.ports.items():
            text = text.replace(listen, local)
        return text

    def listen(self, address: str) -> str:
        """0.0.0.0:PORT -> 127.0.0.1:FREE, also wherever a file or argument names it."""
        return self.ports.setdefault(address, f"127.0.0.1:{free_port()}")

    def mount(self, pod: dict[str, Any], documents: list[Document]) -> None:
        volumes = {v["name"]: v for v in pod["volumes"]}
        (container,) = pod["containers"]
        for mount in container["volumeMounts"]:
            target = self.folder / mount["mountPath"].lstrip("/")
            target.mkdir(parents=True, exist_ok=True)
            volume = volumes[mount["name"]]
            source = volume.get("configMap") or volume.get("secret")
            if source is None:
                continue  # emptyDir
            kind = "ConfigMap" if "configMap" in volume else "Secret"
            name = source.get("name") or source["secretName"]
            files = file_contents(by_kind(documents, kind)[name])
            paths = {i["key"]: i["path"] for i in source.get("items", [])} or \
                {key: key for key in files}
            for key, path in paths.items():
                (target / path).parent.mkdir(parents=True, exist_ok=True)
                (target / path).write_text(self.rewrite(files[key]))


def health(channel: grpc.Channel) -> int:
    stub = health_pb2_grpc.HealthStub(channel)
    return int(stub.Check(health_pb2.HealthCheckRequest(), timeout=5).status)


@pytest.mark.parametrize("pod_name", PODS)
def test_the_pod_serves_as_rendered(cluster: tuple[Path, list[Document]], pod_name: str,
                                    tmp_path: Path) -> None:
    kubernetes, documents = cluster
    pod, isvc = pod_of(documents, pod_name)
    root = Root(tmp_path)
    probe = root.listen("0.0.0.0:50050")  # what overlays/kubernetes.yaml opens
    (container,) = pod["containers"]
    args = [a.replace("{{.Name}}", isvc) for a in container["args"]]
    listen = root.listen(args[args.index("--listen") + 1])
    root.listen(args[args.index("--metrics-listen") + 1])
    root.mount(pod, documents)
    args = [root.rewrite(a) for a in args]
    with oricf_process(*args) as process:
        wait_serving(probe, timeout=180, process=process)  # the kubelet's probe: plaintext
        with grpc.insecure_channel(listen) as plaintext, pytest.raises(grpc.RpcError):
            health(plaintext)  # the service's own port: TLS only
        certs = kubernetes / "certs"
        tls = ClientTls(ca=certs / "ca.pem", cert=certs / "client.pem", key=certs / "client.key")
        token = (("authorization", f"Bearer {(certs / 'tokens').read_text().strip()}"),)
        with tls.channel(listen, []) as channel:
            assert health(channel) == health_pb2.HealthCheckResponse.SERVING
            if pod_name == "detector":
                request = detector_pb2.DetectRequest(image=common_pb2.Image(
                    data=image("person.jpg").read_bytes(), encoding="jpeg"), labels=["person"])
                reply = detector_pb2_grpc.DetectorStub(channel).Detect(request, timeout=10,
                                                                       metadata=token)
                assert count(reply, "person") == 1
            if pod_name == "policy":
                assert_acts(policy_pb2_grpc.PolicyStub(channel), token)
            if isvc:
                stub = oip_grpc.GRPCInferenceServiceStub(channel)
                ready = stub.ModelReady(oip.ModelReadyRequest(name=isvc), timeout=10,
                                        metadata=token)
                assert ready.ready
                with pytest.raises(grpc.RpcError) as refused:  # the one model it was told
                    stub.ModelReady(oip.ModelReadyRequest(name="yolov8-fall"), timeout=10,
                                    metadata=token)
                assert refused.value.code() == grpc.StatusCode.NOT_FOUND


def assert_acts(stub: policy_pb2_grpc.PolicyStub, token: tuple[tuple[str, str], ...]) -> None:
    """Act on the compose smoke test's Hopper observation answers as the policy does here."""
    check = smoke_check()
    request = json_format.ParseDict(check.REQUESTS["policy"](), policy_pb2.Observation())
    with pytest.raises(grpc.RpcError) as refused:
        stub.Act(request, timeout=10)
    assert refused.value.code() == grpc.StatusCode.UNAUTHENTICATED
    reply = stub.Act(request, timeout=10, metadata=token)
    answer = json_format.MessageToDict(reply, preserving_proto_field_name=True)
    assert check.CHECKS["policy"](answer) is None, answer
