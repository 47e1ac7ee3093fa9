"""What orchestrators and balancing clients need from a service: a plaintext health-only port
beside an mTLS one, health watchers that hold no threads, connections that age out."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path

import grpc
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection_pb2, reflection_pb2_grpc

from oricf.errors import ConfigError
from oricf.tls import ClientTls
from oricf.v1 import detector_pb2_grpc
from tests.services.runtime.test_lifecycle import person_request
from tests.support.detections import count
from tests.support.metrics import scrape
from tests.support.processes import free_port
from tests.support.services import running_service
from tests.support.waiting import wait_for

SERVING = health_pb2.HealthCheckResponse.SERVING
NOT_SERVING = health_pb2.HealthCheckResponse.NOT_SERVING


def check(address: str, service: str = "") -> int:
    with grpc.insecure_channel(address) as channel:
        request = health_pb2.HealthCheckRequest(service=service)
        return int(health_pb2_grpc.HealthStub(channel).Check(request, timeout=5).status)


def test_the_health_port_answers_check_in_plaintext_beside_mtls(certs: Path) -> None:
    port = free_port()
    overrides = {"server": {
        "tls": {"cert": str(certs / "server.pem"), "key": str(certs / "server.key"),
                "client_ca": str(certs / "ca.pem")},
        "auth": {"file": str(certs / "tokens")},
        "health_listen": f"127.0.0.1:{port}"}}
    with running_service("detector", overrides, load=False) as service:
        probe = f"127.0.0.1:{port}"
        assert check(probe) == NOT_SERVING  # open, the model not loaded yet
        service.host.load_model()
        assert check(probe) == SERVING
        assert check(probe, "oricf.v1.Detector") == SERVING
        with grpc.insecure_channel(probe) as channel:
            with pytest.raises(grpc.RpcError) as watch:  # Check only: nothing held open
                next(health_pb2_grpc.HealthStub(channel).Watch(
                    health_pb2.HealthCheckRequest(), timeout=5))
            assert watch.value.code() == grpc.StatusCode.UNIMPLEMENTED
            with pytest.raises(grpc.RpcError) as detect:  # and no model RPC without mTLS
                detector_pb2_grpc.DetectorStub(channel).Detect(person_request(), timeout=5)
            assert detect.value.code() == grpc.StatusCode.UNIMPLEMENTED
        # The service's own port still refuses a caller without a client certificate.
        with pytest.raises(grpc.RpcError) as plaintext:
            check(service.address)
        assert plaintext.value.code() == grpc.StatusCode.UNAVAILABLE
        tls = ClientTls(ca=certs / "ca.pem", cert=certs / "client.pem", key=certs / "client.key")
        with tls.channel(service.address, []) as channel:
            reply = health_pb2_grpc.HealthStub(channel).Check(health_pb2.HealthCheckRequest(),
                                                              timeout=5)
            assert reply.status == SERVING
            with pytest.raises(grpc.RpcError) as anonymous:  # reflection needs the token
                list(reflection_pb2_grpc.ServerReflectionStub(channel).ServerReflectionInfo(
                    iter([reflection_pb2.ServerReflectionRequest(list_services="")]),
                    timeout=5))
            assert anonymous.value.code() == grpc.StatusCode.UNAUTHENTICATED
    with pytest.raises(grpc.RpcError):  # stopped with the service
        check(probe)


def test_a_health_port_in_use_names_the_key() -> None:
    with running_service("detector", load=False) as taken, \
            pytest.raises(ConfigError, match=r"server\.health_listen"), \
            running_service("detector", {"server": {"health_listen": taken.address}}, load=False):
        pass


def watch_streams(channel: grpc.Channel, count: int) -> list[grpc.Future]:
    stub = health_pb2_grpc.HealthStub(channel)
    streams = [stub.Watch(health_pb2.HealthCheckRequest(), timeout=30) for _ in range(count)]
    for stream in streams:
        assert next(stream).status == SERVING  # type: ignore[call-overload]
    return streams  # type: ignore[return-value]


def test_health_watchers_hold_no_threads_of_the_service() -> None:
    """A balancing client watches every replica's health for as long as it is connected. A
    detector with one call slot has five threads: ten watchers must not take them from calls."""
    overrides = {"server": {"max_concurrent_rpcs": 1,
                            "metrics": {"listen": "127.0.0.1:0"}}}
    with running_service("detector", overrides) as service:
        streams = watch_streams(service.channel, 10)
        stub = detector_pb2_grpc.DetectorStub(service.channel)
        assert count(stub.Detect(person_request(), timeout=5), "person") == 1
        assert service.host.metrics_server is not None
        url = service.host.metrics_server.url
        labels = {"grpc_service": "grpc.health.v1.Health", "grpc_method": "Watch"}
        assert scrape(url).value("grpc_server_started_total", **labels) == 10
        service.host.health.set("", NOT_SERVING)  # pushed to every watcher
        assert all(next(s).status == NOT_SERVING for s in streams)  # type: ignore[call-overload]
        assert scrape(url).value("grpc_server_msg_sent_total", **labels) == 20
        for stream in streams:
            stream.cancel()
        deadline = time.monotonic() + 5
        while not scrape(url).find("grpc_server_handled_total", grpc_code="CANCELLED", **labels):
            assert time.monotonic() < deadline, "the cancelled watches were never counted"
            time.sleep(0.05)
        time.sleep(0.2)
        assert scrape(url).value("grpc_server_handled_total", grpc_code="CANCELLED",
                                 **labels) == 10


def connectivity(channel: grpc.Channel) -> Iterator[list[grpc.ChannelConnectivity]]:
    states: list[grpc.ChannelConnectivity] = []
    lock = threading.Lock()

    def record(state: grpc.ChannelConnectivity) -> None:
        with lock:
            states.append(state)

    channel.subscribe(record)
    yield states
    channel.unsubscribe(record)


def test_connections_are_closed_at_their_max_age() -> None:
    """GOAWAY after max_connection_age_s: the client connects again (and, with a dns:///
    target, resolves the name again), while a call in flight finishes within grace_s."""
    overrides = {"server": {"max_connection_age_s": 0.5, "grace_s": 2}}
    with running_service("detector", overrides) as service:
        states_of = connectivity(service.channel)
        states = next(states_of)
        stub = detector_pb2_grpc.DetectorStub(service.channel)
        assert count(stub.Detect(person_request(), timeout=5), "person") == 1

        def closed_after_ready() -> bool:
            ready = grpc.ChannelConnectivity.READY
            return ready in states and grpc.ChannelConnectivity.IDLE in states[
                states.index(ready):]

        wait_for(closed_after_ready, timeout=10, what="the connection closed at its max age")
        assert grpc.ChannelConnectivity.IDLE in states[states.index(
            grpc.ChannelConnectivity.READY):]
        assert count(stub.Detect(person_request(), timeout=5), "person") == 1
        next(states_of, None)
