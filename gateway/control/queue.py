"""The action queue of a control loop: each chunk's actions by the step they are for, merged
where chunks overlap, one action taken per tick.

A policy answers an observation with a chunk whose action `i` is for step `start + i`, its
`start_step` (oricf.v1.ActionChunk: the observation's own step for ORICF's policies). By the
time the chunk arrives the robot may be `d` steps further: how the late part is treated
(`late`) and how actions two chunks give for one step are combined (`merge`) are the loop's
settings:

    late: skip     actions for steps already passed are dropped; the chunk is followed on
                   time (delay-aware: what real-time chunking and LeRobot's client do)
    late: shift    the chunk's first action is played at the tick it arrives, as if the
                   observation were fresh (what a client unaware of the delay does)

    merge: latest    the newer chunk's action wins (LeRobot's latest_only)
    merge: weighted  old * (1 - weight) + new * weight (LeRobot's weighted_average, 0.7)
    merge: ensemble  every chunk that predicted the step, weighted exp(-k * i) with i = 0
                     for the oldest (ACT's temporal ensembling, k = 0.01)

(each mode one entry of oricf.gateway.control.merge.MERGES, its settings keys of `merge:`).

A chunk is planned from its observation, and the policy plans so far ahead (its horizon:
its lead and chunk length): an action for a step further than `horizon` steps after the
observation it answers, wherever `late` places it, is dropped, and a chunk whose first
action is that far is refused. So an action planted far ahead is not played seconds later
by a loop the policy has stopped answering: the queue runs out, and the loop holds, then
sends the safe action.

The counts a bench and /metrics report are kept here: ticks with nothing queued, chunks
taken, actions dropped as late or as beyond the horizon, and the jump between consecutive
actions where one chunk's actions give way to another's.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from oricf.gateway.control.merge import MergeMode, merge_mode

Late = Literal["skip", "shift"]


JUMPS_KEPT = 10_000
MAX_CHUNK = 4096     # actions in one chunk
MAX_AHEAD = 4096     # steps a chunk may start after the current one, and the largest horizon


class BadChunk(ValueError):
    """A chunk the queue refuses (wrong shape, values that are not finite)."""


@dataclass
class Counts:
    ticks: int = 0
    empty_ticks: int = 0        # a tick with no action queued for it
    chunks: int = 0             # chunks taken into the queue
    stale_chunks: int = 0       # chunks all of whose actions were late
    late_actions: int = 0       # actions dropped because their step had passed
    ahead_actions: int = 0      # actions dropped as beyond the horizon of their observation
    switches: int = 0           # ticks whose action came from another chunk than the last
    # |a_t - a_t-1| (largest value) at the last JUMPS_KEPT of those switches
    jumps: deque[float] = field(default_factory=lambda: deque(maxlen=JUMPS_KEPT))
    jump_sum: float = 0.0       # of every jump, for the mean


@dataclass(frozen=True)
class Origin:
    """The observation a chunk answers: its step and its capture time (the robot's clock)."""

    step: int
    capture_time_ns: int = 0


@dataclass
class Slot:
    """The actions predicted for one step, oldest chunk first, with the chunk each is from."""

    actions: list[np.ndarray] = field(default_factory=list)
    chunks: list[int] = field(default_factory=list)


class ActionQueue:
    """Thread-safe: the loop's tick thread takes, the thread that receives chunks puts."""

    def __init__(self, action_dim: int, late: Late = "skip",
                 merge: MergeMode | str = "latest", horizon: int = MAX_AHEAD) -> None:
        """`merge`: a mode, or a mode's name (its settings at their defaults)."""
        if not 0 <= horizon <= MAX_AHEAD:
            raise ValueError(f"a horizon of {horizon} steps (0 to {MAX_AHEAD})")
        self.action_dim = action_dim
        self.horizon = horizon      # steps after its observation an action may be for
        self.late = late
        self.merge = merge_mode(merge)
        self.counts = Counts()
        self._slots: dict[int, Slot] = {}
        self._lock = threading.Lock()
        self._last: np.ndarray | None = None
        self._last_chunk = -1
        self._chunk_ids = 0
        self._origins: dict[int, Origin] = {}
        # The observation behind the action `take` returned last (for its age).
        self.last_origin: Origin | None = None

    def put(self, actions: np.ndarray, start_step: int, now: int,
            origin: Origin | None = None) -> int:
        """Queues a chunk whose first action is for `start_step`, arriving when the robot is
        at step `now` (its action for `now` already played); returns how many of its actions
        were queued. `origin`: the observation it answers (the observation step is
        `start_step` when not given)."""
        chunk = self._checked(actions, start_step, now)
        origin = origin or Origin(start_step)
        first = start_step if self.late == "skip" else now + 1
        beyond = origin.step + self.horizon   # the first step past the policy's horizon
        if first > beyond:
            raise BadChunk(f"a chunk for step {first}, {first - origin.step} steps after the "
                           f"observation it answers (step {origin.step}): beyond the horizon "
                           f"of {self.horizon} steps")
        with self._lock:
            self._chunk_ids += 1
            self.counts.chunks += 1
            self._origins[self._chunk_ids] = origin
            queued = 0
            for i, action in enumerate(chunk):
                step = first + i
                if step > beyond:
                    self.counts.ahead_actions += len(chunk) - i
                    break
                if step <= now:
                    self.counts.late_actions += 1
                    continue
                slot = self._slots.setdefault(step, Slot())
                slot.actions.append(action)
                slot.chunks.append(self._chunk_ids)
                queued += 1
            if queued == 0:
                self.counts.stale_chunks += 1
            return queued

    def _checked(self, actions: np.ndarray, start_step: int, now: int) -> np.ndarray:
        """The chunk as float64 rows of the action's size, else BadChunk."""
        chunk = np.asarray(actions, dtype=np.float64)
        if chunk.ndim != 2 or chunk.shape[1] != self.action_dim or len(chunk) == 0:
            raise BadChunk(f"a chunk of shape {list(chunk.shape)}; expected [n, "
                           f"{self.action_dim}]")
        if len(chunk) > MAX_CHUNK:
            raise BadChunk(f"a chunk of {len(chunk)} actions (at most {MAX_CHUNK})")
        if not np.isfinite(chunk).all():
            raise BadChunk("a chunk with values that are not finite")
        if not -MAX_CHUNK <= start_step - now <= MAX_AHEAD:
            raise BadChunk(f"a chunk for step {start_step} at step {now}: not near now")
        return chunk

    def take(self, step: int) -> np.ndarray | None:
        """The action for `step` (None when nothing is queued for it); steps before it are
        forgotten."""
        with self._lock:
            self.counts.ticks += 1
            for passed in [s for s in self._slots if s < step]:
                del self._slots[passed]
            slot = self._slots.pop(step, None)
            if slot is None:
                self.counts.empty_ticks += 1
                self.last_origin = None
                return None
            action = self._combine(slot)
            chunk = slot.chunks[-1]
            self.last_origin = self._origins[chunk]
            self._forget_origins()
            if self._last is not None and chunk != self._last_chunk:
                self.counts.switches += 1
                jump = float(np.max(np.abs(action - self._last)))
                self.counts.jumps.append(jump)
                self.counts.jump_sum += jump
            self._last, self._last_chunk = action, chunk
            return action

    def _forget_origins(self) -> None:
        """Origins of chunks no slot holds any more (and not the one taken last)."""
        held = {chunk for slot in self._slots.values() for chunk in slot.chunks}
        held.add(self._last_chunk)
        for chunk in [c for c in self._origins if c not in held]:
            del self._origins[chunk]

    def remaining(self, step: int) -> int:
        """Actions queued for steps from `step` on, without a gap."""
        with self._lock:
            count = 0
            while step + count in self._slots:
                count += 1
            return count

    def committed(self, step: int) -> tuple[int, np.ndarray]:
        """The actions queued from `step` on as the robot will play them (for real-time
        chunking: sent with the next request)."""
        with self._lock:
            rows: list[np.ndarray] = []
            while step + len(rows) in self._slots:
                rows.append(self._combine(self._slots[step + len(rows)]))
        return step, np.array(rows).reshape(-1, self.action_dim)

    def clear(self) -> None:
        with self._lock:
            self._slots.clear()
            self._origins.clear()
            self._last = None
            self._last_chunk = -1
            self.last_origin = None

    def _combine(self, slot: Slot) -> np.ndarray:
        actions = slot.actions
        return actions[0] if len(actions) == 1 else self.merge.combine(actions)
