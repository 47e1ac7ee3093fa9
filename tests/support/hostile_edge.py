"""A real oricf.v1.Policy server on 127.0.0.1:0 whose answers a test writes, one call at a
time: an edge that names another observation than the one it was sent, plants actions far
ahead or goes silent, as a hostile or broken edge would. Its health says SERVING."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent import futures
from contextlib import contextmanager

import grpc
from grpc_health.v1 import health, health_pb2_grpc

from oricf.v1 import policy_pb2, policy_pb2_grpc

# (the call's index, 0 for the first; its observation) -> the answer, or None: silent (no
# answer until the caller gives up)
Script = Callable[[int, policy_pb2.Observation], "policy_pb2.ActionChunk | None"]


def chunk(request: policy_pb2.Observation, actions: Sequence[Sequence[float]], *,
          start: int | None = None, observation: int | None = None) -> policy_pb2.ActionChunk:
    """An answer of `actions` to `request`: its first action for `start` and saying it
    answers the observation of step `observation` (both the request's step by default)."""
    return policy_pb2.ActionChunk(
        start_step=request.step if start is None else start,
        observation_step=request.step if observation is None else observation,
        capture_time_ns=request.capture_time_ns, action_dim=len(actions[0]),
        actions=[value for action in actions for value in action], model="hostile-edge")


class HostileEdge(policy_pb2_grpc.PolicyServicer):
    def __init__(self, script: Script) -> None:
        self.script = script
        self.calls = 0
        self.steps: list[int] = []      # the step of each call's observation, in order
        self._lock = threading.Lock()
        self.closed = threading.Event()

    def Act(self, request: policy_pb2.Observation,
            context: grpc.ServicerContext) -> policy_pb2.ActionChunk:
        with self._lock:
            index = self.calls
            self.calls += 1
            self.steps.append(request.step)
        reply = self.script(index, request)
        if reply is None:
            while context.is_active() and not self.closed.wait(0.05):
                pass
            context.abort(grpc.StatusCode.UNAVAILABLE, "the edge is silent")
        return reply


@contextmanager
def hostile_edge(script: Script) -> Iterator[tuple[str, HostileEdge]]:
    """The server's address and its servicer (its calls counted)."""
    server = grpc.server(futures.ThreadPoolExecutor(max_workers=8))
    servicer = HostileEdge(script)
    policy_pb2_grpc.add_PolicyServicer_to_server(servicer, server)
    health_pb2_grpc.add_HealthServicer_to_server(health.HealthServicer(), server)
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    try:
        yield f"127.0.0.1:{port}", servicer
    finally:
        servicer.closed.set()
        server.stop(0)
