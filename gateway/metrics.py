"""Prometheus metrics of a pipeline, read at scrape time from the counts its parts keep: the
route workers (inputs received, replaced, dropped, queued), the routes (outcomes, call errors,
latency) and the endpoints (failovers, recoveries, retries, the address in use). Nothing is
counted twice: `oricf gateway`'s periodic stats log line and /metrics read the same numbers.

A `latest` route (camera frames) keeps one pending input, so a newer one replaces it
(inputs_replaced; for a ROS camera also the frames DDS replaced while the route was busy);
a `queue` route (text, audio) discards its oldest input when full (inputs_dropped).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any, Protocol

import grpc
from prometheus_client import CollectorRegistry
from prometheus_client.metrics_core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
    SummaryMetricFamily,
)
from prometheus_client.registry import Collector

from oricf.gateway.config import PipelineConfig
from oricf.gateway.control.loop import ControlLoop
from oricf.gateway.endpoints import Endpoint
from oricf.gateway.endpoints.placement import REASONS
from oricf.gateway.route import Route
from oricf.gateway.worker import RouteWorker
from oricf.metrics import new_registry


class Pipeline(Protocol):
    """The parts of a pipeline whose counts are read (oricf.gateway.pipeline.Pipeline)."""

    config: PipelineConfig
    routes: Mapping[str, Route]
    workers: Mapping[str, RouteWorker[Any]]
    endpoints: Mapping[str, Endpoint]
    speakers: Mapping[str, Any]  # device -> oricf.gateway.sinks.speaker_sink.Speaker
    loops: Mapping[str, ControlLoop]  # route -> its control loop (control inputs)

ROUTE = ("route",)
ENDPOINT = ("endpoint",)
DEVICE = ("device",)
CALL_CODES = frozenset(grpc.StatusCode.__members__)
AGE_STEPS = (0, 1, 2, 4, 8, 16, 32, 64)
# (name, help, where the count is kept) of a control loop's counters
LOOP_COUNTS = (
    ("ticks", "Ticks of the loop (one action each).", "queue", "ticks"),
    ("empty_ticks", "Ticks with no action queued for their step.", "queue", "empty_ticks"),
    ("safe_ticks", "Ticks that sent the safe action.", "loop", "safe_ticks"),
    ("held_ticks", "Ticks that repeated the last action (hold_steps).", "loop", "held_ticks"),
    ("missing_state", "Ticks without an observation (a state part missing, stale or bad).",
     "loop", "missing_state"),
    ("late_ticks", "Ticks that started after their time; the steps passed are skipped.",
     "loop", "late_ticks"),
    ("restarts", "Times the robot's state came back after a silence longer than max_age_ms "
     "(tick: state): what was queued before it was dropped.", "loop", "restarts"),
    ("requests", "Observations sent to the policy.", "loop", "requests"),
    ("chunks", "Chunks taken into the queue.", "loop", "answers"),
    ("expired", "Requests left unanswered past deadline_steps.", "loop", "expired"),
    ("refused_chunks", "Chunks refused: for an observation not asked, older than or as old "
     "as one answered, or another than the request's; or malformed.", "loop",
     "refused_chunks"),
    ("failed", "Requests whose call failed.", "loop", "failed"),
    ("late_actions", "Actions dropped because their step had passed (late: skip).", "queue",
     "late_actions"),
    ("stale_chunks", "Chunks all of whose actions came too late.", "queue", "stale_chunks"),
    ("ahead_actions", "Actions dropped because their step was further after their "
     "observation than max_ahead_ms.", "queue", "ahead_actions"),
)


class PipelineCollector(Collector):
    def __init__(self, pipeline: Pipeline) -> None:
        self._pipeline = pipeline

    def collect(self) -> Iterable[Metric]:
        yield from self._inputs()
        yield from self._outcomes()
        yield from self._endpoints()
        yield from self._speakers()
        yield from self._loops()

    def _inputs(self) -> Iterable[Metric]:
        received = CounterMetricFamily(
            "oricf_gateway_route_inputs_received", "Inputs (frames, texts, utterances, "
            "product values) that reached the route.", labels=ROUTE)
        replaced = CounterMetricFamily(
            "oricf_gateway_route_inputs_replaced", "Inputs of a `latest` route replaced by a "
            "newer one before the route took them (camera frames it had no time for).",
            labels=ROUTE)
        dropped = CounterMetricFamily(
            "oricf_gateway_route_inputs_dropped", "Inputs of a `queue` route discarded, "
            "oldest first, because its queue was full.", labels=ROUTE)
        depth = GaugeMetricFamily("oricf_gateway_route_queue_depth",
                                  "Inputs waiting for the route now.", labels=ROUTE)
        busy = GaugeMetricFamily("oricf_gateway_route_in_progress",
                                 "1 while the route handles an input.", labels=ROUTE)
        for name, worker in self._pipeline.workers.items():
            stats = worker.stats
            received.add_metric((name,), stats.received)
            latest = self._pipeline.config.routes[name].input.mode == "latest"
            replaced.add_metric((name,), stats.dropped if latest else 0)
            dropped.add_metric((name,), 0 if latest else stats.dropped)
            depth.add_metric((name,), worker.depth)
            busy.add_metric((name,), 1 if worker.busy else 0)
        yield from (received, replaced, dropped, depth, busy)

    def _outcomes(self) -> Iterable[Metric]:
        handled = CounterMetricFamily(
            "oricf_gateway_route_inputs_handled", "Inputs the route finished, by outcome: "
            "ok, skipped (nothing to send), bad_input, call_error, internal.",
            labels=("route", "outcome"))
        errors = CounterMetricFamily(
            "oricf_gateway_route_call_errors", "Calls to the route's service that failed "
            "(after any failover and retries), by gRPC status code.",
            labels=("route", "code"))
        latency = HistogramMetricFamily(
            "oricf_gateway_route_latency_seconds", "Time from taking an input to sending its "
            "outputs (call and post-processing included), inputs handled ok.", labels=ROUTE)
        for name, route in self._pipeline.routes.items():
            stats = route.stats
            kinds = dict(stats.errors)
            outcomes = {"ok": stats.ok, "skipped": stats.skipped,
                        "bad_input": stats.bad_input, "call_error": stats.call_errors,
                        "internal": kinds.get("internal", 0)}
            for outcome, count in outcomes.items():
                handled.add_metric((name, outcome), count)
            for code, count in sorted(kinds.items()):
                if code in CALL_CODES:
                    errors.add_metric((name, code), count)
            buckets, total = stats.latency.snapshot()
            latency.add_metric((name,), buckets, total)
        yield from (handled, errors, latency)

    def _endpoints(self) -> Iterable[Metric]:
        failovers = CounterMetricFamily(
            "oricf_gateway_endpoint_failovers", "Switches from the primary to the fallback "
            "(the primary answered UNAVAILABLE or DEADLINE_EXCEEDED).", labels=ENDPOINT)
        recoveries = CounterMetricFamily(
            "oricf_gateway_endpoint_recoveries", "Returns to the primary once its health "
            "check said SERVING again.", labels=ENDPOINT)
        retries = CounterMetricFamily(
            "oricf_gateway_endpoint_retries", "Calls retried because the service refused them "
            "as busy (RESOURCE_EXHAUSTED).", labels=ENDPOINT)
        placements = CounterMetricFamily(
            "oricf_gateway_endpoint_placements", "Moves between the primary and the fallback "
            f"by the placement policy (placement:), by reason: {', '.join(REASONS)}.",
            labels=("endpoint", "reason"))
        active = GaugeMetricFamily(
            "oricf_gateway_endpoint_active", "1 for the address the endpoint calls now, 0 for "
            "the other.", labels=("endpoint", "role", "address"))
        for name, endpoint in self._pipeline.endpoints.items():
            failovers.add_metric((name,), endpoint.failovers)
            recoveries.add_metric((name,), endpoint.recoveries)
            retries.add_metric((name,), endpoint.retries)
            if endpoint.placement is not None:
                for reason in REASONS:
                    placements.add_metric((name, reason),
                                          endpoint.placement.decisions[reason])
            in_use = endpoint.active
            targets = [("primary", endpoint.primary)]
            if endpoint.fallback is not None:
                targets.append(("fallback", endpoint.fallback))
            for role, target in targets:
                active.add_metric((name, role, target.address), 1 if target is in_use else 0)
        yield from (failovers, recoveries, retries, placements, active)

    def _speakers(self) -> Iterable[Metric]:
        played = CounterMetricFamily(
            "oricf_gateway_speaker_pieces_played", "Pieces of speech (a sentence or an "
            "answer) played to the end on the device.", labels=DEVICE)
        dropped = CounterMetricFamily(
            "oricf_gateway_speaker_pieces_dropped", "Pieces of speech never played: queued "
            "when a barge-in came, asked before it, or left when the device was lost.",
            labels=DEVICE)
        cut = CounterMetricFamily(
            "oricf_gateway_speaker_answers_cut", "Answers cut while playing by a barge-in "
            "(a new utterance on a `barge_in` microphone).", labels=DEVICE)
        playing = GaugeMetricFamily("oricf_gateway_speaker_playing",
                                    "1 while the device plays speech.", labels=DEVICE)
        for device, speaker in self._pipeline.speakers.items():
            stats = speaker.stats
            played.add_metric((device,), stats.played)
            dropped.add_metric((device,), stats.dropped)
            cut.add_metric((device,), stats.cut)
            playing.add_metric((device,), 1 if speaker.playing else 0)
        yield from (played, dropped, cut, playing)

    def _loops(self) -> Iterable[Metric]:
        counters = {name: CounterMetricFamily(f"oricf_gateway_control_{name}", text,
                                              labels=ROUTE)
                    for name, text, _, _ in LOOP_COUNTS}
        age = HistogramMetricFamily(
            "oricf_gateway_control_action_age_seconds", "Age of the observation behind each "
            "action sent (from receiving its state to sending the action).", labels=ROUTE)
        age_steps = HistogramMetricFamily(
            "oricf_gateway_control_action_age_steps", "Age in control steps of the "
            "observation behind each action sent (the last 10000).", labels=ROUTE)
        cpu = CounterMetricFamily(
            "oricf_gateway_control_cpu_seconds", "CPU time of the loop's own work on its "
            "threads, by work: tick (taking the state and images, assembling the "
            "observation, merging, publishing) and request (the message, the call on its "
            "thread, taking the answer); gRPC's and ROS's own threads are not in it.",
            labels=(*ROUTE, "work"))
        jumps = SummaryMetricFamily(
            "oricf_gateway_control_switch_jump", "Where one chunk's actions give way to "
            "another's: the largest change of a value between the two actions.", labels=ROUTE)
        for route, loop in self._pipeline.loops.items():
            for name, _, owner, attr in LOOP_COUNTS:
                counts = loop.queue.counts if owner == "queue" else loop.counts
                counters[name].add_metric((route,), getattr(counts, attr))
            buckets, total = loop.ages.seconds.snapshot()
            age.add_metric((route,), buckets, total)
            kept = list(loop.ages.steps)
            age_steps.add_metric((route,), [(str(b), float(sum(a <= b for a in kept)))
                                            for b in AGE_STEPS] + [("+Inf", float(len(kept)))],
                                 float(sum(kept)))
            cpu.add_metric((route, "tick"), loop.counts.tick_cpu_ns / 1e9)
            cpu.add_metric((route, "request"), loop.counts.request_cpu_ns / 1e9)
            counts = loop.queue.counts
            jumps.add_metric((route,), counts.switches, counts.jump_sum)
        yield from (*counters.values(), age, age_steps, cpu, jumps)


def pipeline_registry(pipeline: Pipeline) -> CollectorRegistry:
    registry = new_registry()
    registry.register(PipelineCollector(pipeline))
    return registry
