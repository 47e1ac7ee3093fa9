"""Token loop: tokens -> text pieces, with stop sequences, a token limit and a cancel check.

Written over llama-cpp-python's low-level `Llama.generate` rather than `create_completion`
so that the caller's check runs after every token (a client that goes away costs at most
one more token), the token counts are exact, and the loop's state is plain to see; the
sampler chain that `generate` makes is freed when the loop ends (release_sampler).
"""

from __future__ import annotations

import codecs
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Sampling:
    temperature: float
    top_k: int
    top_p: float
    min_p: float
    repeat_penalty: float


@dataclass
class LoopResult:
    """Filled in while the loop runs; read when it ends (or is cut short)."""

    finish_reason: str = ""
    completion_tokens: int = 0
    first_token_at: float | None = None


class StopScanner:
    """Holds back text that could be the start of a stop sequence; cuts at the first stop."""

    def __init__(self, stops: Sequence[str]) -> None:
        self.stops = [s for s in dict.fromkeys(stops) if s]
        self._pending = ""

    def feed(self, text: str) -> tuple[str, bool]:
        """(text safe to emit now, whether a stop sequence was reached)."""
        self._pending += text
        hits = [i for i in (self._pending.find(s) for s in self.stops) if i >= 0]
        if hits:
            out, self._pending = self._pending[:min(hits)], ""
            return out, True
        keep = self._partial_stop_length()
        cut = len(self._pending) - keep
        out, self._pending = self._pending[:cut], self._pending[cut:]
        return out, False

    def flush(self) -> str:
        out, self._pending = self._pending, ""
        return out

    def _partial_stop_length(self) -> int:
        """Length of the longest tail of the pending text that begins some stop sequence."""
        best = 0
        for stop in self.stops:
            for size in range(min(len(stop) - 1, len(self._pending)), best, -1):
                if self._pending.endswith(stop[:size]):
                    best = size
                    break
        return best


def release_sampler(llm: Any) -> None:
    """Frees the sampler chain that `Llama.generate` made for this generation, now.

    llama-cpp-python keeps the chain on the Llama until the next generate replaces it, and
    the chain's Python object sits in a reference cycle, so its native memory (buffers the
    size of the vocabulary) waited for the garbage collector's rare full passes: the
    service's anonymous memory climbed by megabytes per generation under a steady stream
    of requests. Closing it is what its own finalizer does, a generation sooner.
    """
    sampler, llm._sampler = getattr(llm, "_sampler", None), None
    if sampler is not None:
        sampler.close()


def run_tokens(llm: Any, tokens: list[int], sampling: Sampling, max_tokens: int,
               stops: Sequence[str], is_end: Callable[[int], bool], check: Callable[[], None],
               result: LoopResult, clock: Callable[[], float], grammar: Any = None
               ) -> Iterator[str]:
    """Generates from `tokens`, yielding text as it is produced (leading blanks dropped).

    check() runs after every token and raises to stop at once; `result` then still holds
    the count of tokens generated so far. A grammar (llama_cpp.LlamaGrammar) constrains
    which tokens may come.
    """
    started = False
    for text in _run(llm, tokens, sampling, max_tokens, stops, is_end, check, result, clock,
                     grammar):
        if not started:
            # "Answer:" prompts make the first token " I"; the answer itself has no blank.
            text = text.lstrip()
            started = bool(text)
        if text:
            yield text


def _run(llm: Any, tokens: list[int], sampling: Sampling, max_tokens: int,
         stops: Sequence[str], is_end: Callable[[int], bool], check: Callable[[], None],
         result: LoopResult, clock: Callable[[], float], grammar: Any) -> Iterator[str]:
    scanner = StopScanner(stops)
    decoder = codecs.getincrementaldecoder("utf-8")(errors="replace")
    generator = llm.generate(
        tokens, temp=sampling.temperature, top_k=sampling.top_k, top_p=sampling.top_p,
        min_p=sampling.min_p, repeat_penalty=sampling.repeat_penalty, grammar=grammar)
    try:
        for token in generator:
            if result.first_token_at is None:
                result.first_token_at = clock()
            check()
            if is_end(token):
                result.finish_reason = "stop"
                break
            result.completion_tokens += 1
            text, stopped = scanner.feed(decoder.decode(llm.detokenize([token])))
            if text:
                yield text
            if stopped:
                result.finish_reason = "stop"
                return
            if result.completion_tokens >= max_tokens:
                result.finish_reason = "length"
                break
    finally:
        # Leaves the llama.cpp state consistent (the KV cache holds what was evaluated).
        generator.close()
        release_sampler(llm)
    tail = scanner.feed(decoder.decode(b"", final=True))[0] + scanner.flush()
    if tail:
        yield tail
