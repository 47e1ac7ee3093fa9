"""Open Inference Protocol requests to one declared model, run in shared batches.

A request's tensors carry their batch along the first dimension. Requests whose tensors
agree on everything else (names, datatypes, the other dimensions) run joined, as many rows
as max_batch_size allows in one run; the rest run in runs of their own. Each request gets
its own rows of every output back.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from oricf.errors import InvalidInput
from oricf.models.declared import DeclaredModel

Feeds = dict[str, np.ndarray]


def rows_of(model: DeclaredModel, feeds: Feeds, max_batch_size: int) -> int:
    """The request's batch (its tensors' first dimension), each tensor checked first so a
    bad request never fails a batch it would have joined."""
    for spec in model.inputs:
        if spec.name not in feeds:
            raise InvalidInput(f"model {model.name}: input '{spec.name}' is missing")
        model.input(spec.name).check(feeds[spec.name])
    rows = {array.shape[0] for array in feeds.values()}
    if len(rows) != 1:
        raise InvalidInput(f"model {model.name}: the inputs disagree on the batch (first "
                           f"dimension): {sorted(rows)}")
    (count,) = rows
    if not 1 <= count <= max_batch_size:
        raise InvalidInput(f"model {model.name}: a batch of {count} rows; this server "
                           f"batches 1 to {max_batch_size} (batching.max_batch_size)")
    return count


def _key(feeds: Feeds) -> tuple[tuple[str, str, tuple[int, ...]], ...]:
    return tuple(sorted((name, str(a.dtype), a.shape[1:]) for name, a in feeds.items()))


def batch_runner(model: DeclaredModel, max_batch_size: int
                 ) -> Callable[[list[Feeds]], list[Feeds | Exception]]:
    """run_batch for a Batcher of this model's requests."""

    def run(items: list[Feeds]) -> list[Feeds | Exception]:
        results: list[Feeds | Exception | None] = [None] * len(items)
        groups: dict[tuple[tuple[str, str, tuple[int, ...]], ...], list[int]] = {}
        for i, feeds in enumerate(items):
            groups.setdefault(_key(feeds), []).append(i)
        for members in groups.values():
            chunk: list[int] = []
            rows = 0
            for i in members:
                count = len(next(iter(items[i].values())))
                if chunk and rows + count > max_batch_size:
                    _run_chunk(model, items, chunk, results)
                    chunk, rows = [], 0
                chunk.append(i)
                rows += count
            _run_chunk(model, items, chunk, results)
        return [r if r is not None else RuntimeError("no result") for r in results]

    return run


def _run_chunk(model: DeclaredModel, items: list[Feeds], chunk: list[int],
               results: list[Feeds | Exception | None]) -> None:
    try:
        outputs: list[Feeds | Exception] = list(model.infer_batch([items[i] for i in chunk]))
    except Exception as exc:
        outputs = [exc] * len(chunk)
    for i, output in zip(chunk, outputs, strict=True):
        results[i] = output
