"""Dynamic batching: requests from different callers share one inference.

A small version of Triton's dynamic batcher. A caller submits an item and waits on its
ticket. A batch is released when `max_batch_size` items wait or `max_queue_delay_ms` has
passed since the oldest arrived; the `instances` worker threads that are idle then share it
(on a CPU two batches of one on two cores beat one batch of two on one core), and each runs
its part in one call of `run_batch(items) -> results` (a result may be an exception: that
item's error alone). While instances are busy the queue fills: batches grow with the load.
Before a batch runs, items whose caller's deadline has passed are answered
DeadlineExceeded and items whose caller went away are left out. The queue is bounded: an
item beyond `max_queue_size` is refused at once with Overloaded, with the same retry hint
as the call limit (RESOURCE_EXHAUSTED, grpc-retry-pushback-ms).

Stopping: flush() stops the waiting for batches to fill (the service is draining: run
what is there); close() refuses new items, runs those queued and joins the workers.
Nothing here knows gRPC: the servicer turns the caller's deadline into a monotonic time
and the call's end into ticket.cancel().
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Sequence
from typing import Generic, TypeVar

from pydantic import Field

from oricf.config import Schema
from oricf.errors import Cancelled, DeadlineExceeded, NotReady, Overloaded
from oricf.services.runtime.limits import pushback_ms

log = logging.getLogger(__name__)

# gRPC ends a call at its deadline by its own clock: a call ended this close to the deadline
# we computed from time_remaining() ended by it, not by the caller.
CLOCK_SLACK_S = 0.05

T = TypeVar("T")
R = TypeVar("R")
RunBatch = Callable[[list[T]], Sequence[R | Exception]]


class BatchingSettings(Schema):
    """A `batching:` block: Triton's dynamic_batching, in milliseconds."""

    max_batch_size: int = Field(8, ge=1, le=256, description="items run in one inference")
    max_queue_delay_ms: float = Field(
        5.0, ge=0, le=10_000,
        description="how long the oldest waiting item may wait for others to join its batch")
    max_queue_size: int = Field(
        64, ge=1, le=10_000,
        description="items waiting beyond this are refused RESOURCE_EXHAUSTED at once")
    instances: int = Field(
        1, ge=1, le=64, description="batches that run at the same time (worker threads)")
    fixed_size: bool | None = Field(
        None, description="every batch runs at max_batch_size rows, padded: on a GPU a new "
                          "batch size is planned anew (seconds with onnxruntime's CUDA "
                          "provider); null: where the model runs on an accelerator")


class Ticket(Generic[T, R]):
    """One submitted item: wait for its result with result(), give up with cancel()."""

    def __init__(self, batcher: Batcher[T, R], item: T, deadline: float | None) -> None:
        self.item = item
        self.deadline = deadline      # time.monotonic() after which the caller is gone
        self.enqueued = time.monotonic()
        self._batcher = batcher
        self._done = threading.Event()
        self._result: R | None = None
        self._error: BaseException | None = None

    def result(self) -> R:
        """The item's result; raises its error, or DeadlineExceeded when the deadline passes
        first (the item is then taken out of the queue if it is still there)."""
        timeout = None if self.deadline is None else max(0.0, self.deadline - time.monotonic())
        if not self._done.wait(timeout):
            self._batcher._withdraw(self, DeadlineExceeded(
                "the deadline passed while the request waited for a batch"))
            self._done.wait()
        if self._error is not None:
            raise self._error
        return self._result  # type: ignore[return-value]

    def cancel(self) -> None:
        """The caller went away: leave the queue (a batch already running is not stopped).
        A call ended by its deadline counts as such."""
        self._batcher._withdraw(self, DeadlineExceeded(
            "the deadline passed while the request waited for a batch")
            if self.expired(time.monotonic() + CLOCK_SLACK_S) else
            Cancelled("the call ended before its batch ran"))

    def expired(self, now: float) -> bool:
        return self.deadline is not None and now >= self.deadline

    def finish(self, result: R | None = None, error: BaseException | None = None) -> None:
        if not self._done.is_set():
            self._result, self._error = result, error
            self._done.set()


class BatchStats:
    """What the metrics report: batch sizes, and items that never reached a batch."""

    def __init__(self) -> None:
        self.sizes: Counter[int] = Counter()  # batch size -> batches run
        self.dropped: Counter[str] = Counter()  # "deadline" | "cancelled" | "refused"


class Batcher(Generic[T, R]):
    def __init__(self, name: str, settings: BatchingSettings, run_batch: RunBatch[T, R],
                 retry_after_ms: int) -> None:
        self.name = name
        self.settings = settings
        self.stats = BatchStats()
        self._run_batch = run_batch
        self._retry_after_ms = retry_after_ms
        self._queue: deque[Ticket[T, R]] = deque()
        self._cond = threading.Condition()
        self._hurry = False   # flushing: run what waits without waiting for more
        self._closed = False
        self._idle = 0        # workers waiting for a batch, not running one
        self._fired = 0       # items at the front of the queue released to run now
        self._workers = [threading.Thread(target=self._work, name=f"{name}-batch-{i}",
                                          daemon=True) for i in range(settings.instances)]
        for worker in self._workers:
            worker.start()

    @property
    def queued(self) -> int:
        with self._cond:
            return len(self._queue)

    def snapshot(self) -> tuple[dict[int, int], dict[str, int], int]:
        """Batch size -> batches run, reason -> items dropped, items waiting now."""
        with self._cond:
            return dict(self.stats.sizes), dict(self.stats.dropped), len(self._queue)

    def submit(self, item: T, deadline: float | None = None) -> Ticket[T, R]:
        """Queues an item; raises Overloaded when the queue is full, NotReady once closed."""
        ticket = Ticket(self, item, deadline)
        with self._cond:
            if self._closed:
                raise NotReady("the service is shutting down; retry shortly")
            if len(self._queue) >= self.settings.max_queue_size:
                self.stats.dropped["refused"] += 1
                wait_ms = pushback_ms(self._retry_after_ms)
                raise Overloaded(f"the batch queue is full ({len(self._queue)} requests "
                                 f"waiting); retry in {wait_ms} ms", retry_after_ms=wait_ms)
            self._queue.append(ticket)
            self._cond.notify_all()
        return ticket

    def flush(self) -> None:
        """From now on, run what waits without waiting for batches to fill."""
        with self._cond:
            self._hurry = True
            self._cond.notify_all()

    def close(self, timeout: float = 30.0) -> None:
        """Refuses new items, runs the queued ones, and joins the workers."""
        with self._cond:
            self._closed = self._hurry = True
            self._cond.notify_all()
        for worker in self._workers:
            worker.join(timeout)

    def _withdraw(self, ticket: Ticket[T, R], error: BaseException) -> None:
        with self._cond:
            if ticket in self._queue:  # not yet taken into a batch
                self._queue.remove(ticket)
                self.stats.dropped["cancelled" if isinstance(error, Cancelled)
                                   else "deadline"] += 1
                ticket.finish(error=error)

    def _work(self) -> None:
        while (batch := self._next_batch()) is not None:
            self._run(batch)

    def _next_batch(self) -> list[Ticket[T, R]] | None:
        """Blocks for the next batch (None once closed and empty)."""
        with self._cond:
            self._idle += 1
            try:
                return self._form_batch()
            finally:
                self._idle -= 1

    def _form_batch(self) -> list[Ticket[T, R]] | None:
        settings = self.settings
        while True:
            while not self._queue:
                self._fired = 0
                if self._closed:
                    return None
                self._cond.wait()
            if not self._fired:
                # Wait for the batch to fill, at most the delay after its oldest item came.
                form_until = self._queue[0].enqueued + settings.max_queue_delay_ms / 1e3
                while self._queue and not self._fired and not self._hurry \
                        and len(self._queue) < settings.max_batch_size:
                    left = form_until - time.monotonic()
                    if left <= 0:
                        break
                    self._cond.wait(left)
                if not self._queue:
                    continue
                if not self._fired:  # full, or waited long enough: it runs now
                    self._fired = min(len(self._queue), settings.max_batch_size)
                    self._cond.notify_all()
            # What runs now is shared among the idle instances: on a CPU, two batches of
            # one on two cores finish sooner than one batch of two on one core.
            fired = min(self._fired, len(self._queue))
            share = -(-fired // max(self._idle, 1))
            popped, batch = self._take(share)
            self._fired = max(0, fired - popped)
            if batch:
                return batch

    def _take(self, count: int) -> tuple[int, list[Ticket[T, R]]]:
        """Pops `count` items off the front of the queue (the lock is held); returns how
        many it popped and those whose caller still waits."""
        now = time.monotonic()
        batch: list[Ticket[T, R]] = []
        popped = 0
        while self._queue and popped < count:
            ticket = self._queue.popleft()
            popped += 1
            if ticket.expired(now):  # its caller has given up: never run it
                self.stats.dropped["deadline"] += 1
                ticket.finish(error=DeadlineExceeded(
                    "the deadline passed while the request waited for a batch"))
                continue
            batch.append(ticket)
        return popped, batch

    def _run(self, batch: list[Ticket[T, R]]) -> None:
        try:
            results = self._run_batch([ticket.item for ticket in batch])
            if len(results) != len(batch):
                raise RuntimeError(f"{self.name}: a batch of {len(batch)} gave "
                                   f"{len(results)} results")
        except Exception as exc:  # the whole batch failed: each caller gets the error
            for ticket in batch:
                ticket.finish(error=exc)
        else:
            for ticket, result in zip(batch, results, strict=True):
                if isinstance(result, Exception):
                    ticket.finish(error=result)
                else:
                    ticket.finish(result=result)
        with self._cond:
            self.stats.sizes[len(batch)] += 1
        log.debug("%s: ran a batch of %d", self.name, len(batch))
