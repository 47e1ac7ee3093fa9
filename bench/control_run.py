"""One episode of a declared policy in a simulator through the gateway's control loop
(oricf.gateway.control), in simulated time: the loop's own tick, its clock the simulator's
steps, its transport a wire that holds each answer for the round trip.

A round trip of `d` steps: a request sent at step `t` (asked before the action for `t`) is
delivered before the action for `t + d`; `d = 0` is the same tick (onboard). The policy is
the same declared model either way (PolicyModel); only the delay differs. The robot side's
CPU per tick is counted with the thread's CPU clock around the loop's own work (delivering
answers, asking, the request's message, taking the action, the message it publishes), and
the policy's call only where the policy runs on the robot.
"""

from __future__ import annotations

import logging
import math
import time
from collections import defaultdict
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from oricf.bench.sims import Sim
from oricf.gateway.control.loop import ControlLoop, Request
from oricf.gateway.control.queue import ActionQueue, Counts, Late, Origin
from oricf.gateway.endpoints.placement import MIN_SAMPLES, PlacementConfig
from oricf.gateway.endpoints.placement import Placement as GatewayPlacement
from oricf.models.policy import PolicyModel

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Setting:
    """How the loop is set for one mode at one delay."""

    late: Late
    merge: str                  # a merge mode's name (oricf.gateway.control.merge)
    request_at: int
    max_in_flight: int
    delay_steps: int
    policy_onboard: bool        # the policy's call is the robot's CPU
    blind: bool = False         # the cameras' images blanked (all zeros) before they go
    send_committed: bool = False  # the actions already queued go with each request


@dataclass
class Episode:
    total_return: float
    steps: int                  # to success (metaworld), else the episode's length
    success: bool
    ages: list[int]             # steps from each played action's observation to its tick
    counts: Counts
    cpu_ns: int                 # the robot side's CPU over the episode
    ticks: int


@dataclass
class Wire:
    """Answers on their way back, by the step they are delivered before."""

    delay_steps: int
    due: dict[int, list[tuple[list[float], int, Origin]]] = field(
        default_factory=lambda: defaultdict(list))

    def send(self, step: int, answer: list[float], start_step: int, origin: Origin) -> None:
        self.due[step + self.delay_steps].append((answer, start_step, origin))

    def arrive(self, loop: ControlLoop, step: int, chunk: int, dim: int) -> None:
        """Delivers what is due before the action for `step` (the answer as the robot gets
        it: a flat list, made an array here, and the step its first action is for)."""
        for answer, start_step, origin in self.due.pop(step, []):
            actions = np.asarray(answer, np.float64).reshape(chunk, dim)
            loop.deliver(actions, start_step, origin, now=step - 1)


def answer(policy: PolicyModel, message: list[float],
           images: Mapping[str, np.ndarray] | None = None,
           committed: tuple[int, np.ndarray] | None = None) -> list[float]:
    """The policy's chunk for a state as it went over the wire (and the cameras' images and
    the actions committed that went with it: from which step after the state's, which), as
    it comes back."""
    chunk = policy.act(np.asarray(message, np.float32), images, committed)
    return list(chunk.reshape(-1).tolist())


def camera_views(sim: Sim, blind: bool) -> dict[str, np.ndarray] | None:
    """The sim's cameras' views now (None without cameras); blind: each blanked, all zeros
    of its size, as a policy without its cameras would see them."""
    if not sim.cameras:
        return None
    views = sim.images()
    return {name: np.zeros_like(view) for name, view in views.items()} if blind else views


def control_loop(sim: Sim, setting: Setting, max_steps: int) -> ControlLoop:
    queue = ActionQueue(sim.action_dim, setting.late, setting.merge)
    # The last action is held while an answer is on its way (the safe action, zeros, only
    # before the first); a request may stay out for the round trip and one step more.
    return ControlLoop(queue, np.zeros(sim.action_dim), setting.request_at,
                       deadline=setting.delay_steps + 1, hold_steps=max_steps,
                       send_committed=setting.send_committed,
                       max_in_flight=setting.max_in_flight)


def run_episode(sim: Sim, policy: PolicyModel, setting: Setting, seed: int,
                max_steps: int) -> Episode:
    loop = control_loop(sim, setting, max_steps)
    wire = Wire(setting.delay_steps)
    chunk, dim = policy.task.chunk, sim.action_dim
    observation = sim.reset(seed)
    episode = Episode(0.0, 0, False, [], loop.queue.counts, 0, 0)
    played: Origin | None = None
    for step in range(min(max_steps, sim.max_steps)):
        images = camera_views(sim, setting.blind)  # the camera's work, not the loop's
        start = time.thread_time_ns()
        wire.arrive(loop, step, chunk, dim)
        request = loop.ask(step, observation, now_ns=step, images=images)
        message = request.state.tolist() if request is not None else None
        mark = time.thread_time_ns()
        episode.cpu_ns += mark - start
        if request is not None and message is not None:
            committed = None if request.committed is None else (
                request.committed[0] - step, request.committed[1])
            reply = answer(policy, message, request.images, committed)
            if setting.policy_onboard:
                episode.cpu_ns += time.thread_time_ns() - mark
            send(wire, request, reply, policy.task.lead_steps)
        start = time.thread_time_ns()
        wire.arrive(loop, step, chunk, dim)
        tick = loop.act(step)
        published = tick.action.tolist()
        episode.cpu_ns += time.thread_time_ns() - start
        played = tick.origin or (None if tick.safe else played)
        if played is not None:
            episode.ages.append(step - played.step)
        result = sim.step(np.asarray(published))
        observation = result.observation
        episode.total_return += result.reward
        episode.ticks = step + 1
        if result.success and not episode.success:
            episode.success, episode.steps = True, step + 1
            break
        if result.done:
            break
    if not episode.success:
        episode.steps = episode.ticks
    return episode


def send(wire: Wire, request: Request, reply: list[float], lead_steps: int) -> None:
    """The answer as the policy service gives it: its first action for the observation's
    step plus the policy's declared lead."""
    wire.send(request.step, reply, request.step + lead_steps,
              Origin(request.step, request.capture_time_ns))


def delay_steps(delay_ms: float, rate_hz: float) -> int:
    """Whole control steps a round trip of `delay_ms` takes (a part of a step is a step:
    the answer misses that tick); the tolerance keeps 33 ms at 60.6 Hz two steps, not three."""
    return max(0, math.ceil(delay_ms * rate_hz / 1000 - 1e-6))


MODES = ("onboard", "edge-sync", "edge-latest", "edge-weighted", "edge-ensemble", "edge-ahead",
         "placed")
BLIND = "onboard-blind"  # onboard, the cameras' images blanked: added for a sim with cameras
# Modes run only when asked for (--modes): edge-committed trains a policy per round trip
# with DAgger rounds, minutes each on two cores.
OPTIONAL_MODES = ("edge-committed",)
# need a policy trained for the round trip: metaworld only
TRAINED_MODES = ("edge-ahead", "edge-committed")
MERGES: dict[str, str] = {"edge-latest": "latest", "edge-weighted": "weighted",
                          "edge-ensemble": "ensemble"}


def ask_ahead(chunk: int) -> int:
    """The queue's length at which the next chunk is asked for: `chunk - 1`, so a new
    request goes out as soon as the last answer is in (one in flight): the freshest chunk a
    single request at a time gives, a new one every round trip; a policy of one action is
    asked every tick. (Asking later, `d + 1` actions ahead, asks less often and did worse
    on pick-place-v3: docs/control.md.)"""
    return chunk - 1


def setting(mode: str, delay_steps: int, chunk: int) -> Setting:
    """The loop's settings for `mode` (not `placed`: see placement) at a round trip of
    `delay_steps`. `edge-ahead` is `edge-latest` for a policy trained to act `delay_steps`
    ahead: its chunk starts at the step it arrives at, so `chunk` actions are queued then,
    and asking at `chunk` asks as soon as it is in, as the other delay-aware modes do."""
    if mode in ("onboard", BLIND):  # each chunk played through, then the next asked for
        return Setting("skip", "latest", 0, 1, 0, True, blind=mode == BLIND)
    if mode == "edge-sync":
        if chunk == 1:  # pipelined: the robot acts on observations `d` steps old
            return Setting("shift", "latest", 1, delay_steps + 1, delay_steps, False)
        return Setting("shift", "latest", 0, 1, delay_steps, False)
    if mode == "edge-ahead":  # a chunk arrives with every action ahead: `chunk` queued
        return Setting("skip", "latest", chunk, 1, delay_steps, False)
    if mode == "edge-committed":  # edge-ahead, the actions committed sent with the request
        return Setting("skip", "latest", chunk, 1, delay_steps, False, send_committed=True)
    return Setting("skip", MERGES[mode], ask_ahead(chunk), 1, delay_steps,
                   False)


@dataclass(frozen=True)
class Placed:
    mode: str                   # the mode the placed policy runs as
    onboard: bool
    reason: str


def placement(delay_ms: float, rate_hz: float, budget_steps: int, chunk: int) -> Placed:
    """Where the gateway's placement (oricf.gateway.endpoints.placement, a budget in steps)
    puts the policy once it has timed the edge's first calls at `delay_ms`: onboard when
    their p90 is over the budget, else on the edge, delay-aware (edge-latest) for a chunk
    policy; a policy of one action has no later action to skip to, so it runs pipelined
    (edge-sync) there."""
    rule = GatewayPlacement("policy", PlacementConfig(latency_budget_steps=budget_steps),
                step_s=1 / rate_hz)
    for _ in range(MIN_SAMPLES):
        rule.call_took(delay_ms / 1e3)
    steps = delay_steps(delay_ms, rate_hz)
    trip = f"the edge's round trip of {delay_ms:g} ms ({_steps(steps)})"
    if rule.moved:
        return Placed("onboard", True, f"onboard: {trip} is over the budget of "
                         f"{rule.budget_text}")
    edge = "edge-latest" if chunk > 1 else "edge-sync"
    return Placed(edge, False, f"edge ({edge}): {trip} is within the budget of "
                     f"{rule.budget_text}")


def _steps(count: int) -> str:
    return f"{count} step" if count == 1 else f"{count} steps"


def default_budget(chunk: int) -> int:
    """Steps of round trip a policy is given by default: one for a policy of one action;
    half a chunk for a chunk policy, the longest round trip over which one request at a
    time keeps the queue from running dry (an answer leaves `chunk - d` actions to play
    while the next request, sent as it arrives, takes `d` steps)."""
    return 1 if chunk == 1 else chunk // 2
