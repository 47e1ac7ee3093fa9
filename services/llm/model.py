"""A GGUF language model on llama.cpp (llama-cpp-python): load(), generate(), close(), info().

Knows nothing of gRPC: the caller passes a `still_wanted` check that raises Cancelled or
DeadlineExceeded, and the model calls it between tokens and while waiting for its turn.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Generator, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from oricf.errors import InvalidInput, NotReady, OricfError
from oricf.services.llm.decode import LoopResult, Sampling, run_tokens
from oricf.services.llm.domain import (
    Chunk,
    Finished,
    GenerationRequest,
    GenerationStats,
    StillWanted,
)
from oricf.services.llm.gate import GenerationGate
from oricf.services.llm.grammar import json_grammar
from oricf.services.llm.prompt import PromptRenderer, PromptTemplate
from oricf.services.runtime import ModelInfo

log = logging.getLogger(__name__)

# GenerationStats.last_finish_reason when the consumer stopped reading mid-way.
ABANDONED = "abandoned"
CLOSE_WAIT_S = 5.0


@dataclass(frozen=True)
class LlamaSettings:
    path: Path
    catalog_name: str
    sha256: str
    license: str
    template: PromptTemplate
    prompt_file: str
    n_ctx: int
    n_batch: int
    threads: int
    omp_wait_policy: str
    reuse_prefix: bool
    sampling: Sampling          # temperature here is the default; requests may override it
    max_waiting: int
    wait_timeout_s: float
    gpu_layers: int = 0         # -1: all; 0: none (CPU)


def _ms(start: float, end: float) -> float:
    return (end - start) * 1e3


def llama_devices(llama_cpp: Any, gpu_layers: int) -> list[str]:
    """Where the layers run: the GPU back ends llama.cpp was built with (from its system
    info, e.g. "CUDA"), then the CPU; the CPU alone when none is asked for or none is built
    in, which one log line says."""
    if gpu_layers == 0:
        return ["CPU"]
    if not llama_cpp.llama_supports_gpu_offload():
        log.warning("model.gpu_layers %d: this llama.cpp was built without a GPU back end; "
                    "the model runs on the CPU (docs/platforms.md: llama.cpp with CUDA)",
                    gpu_layers)
        return ["CPU"]
    info = llama_cpp.llama_print_system_info().decode(errors="replace")
    gpus = [part.split(":")[0].strip() for part in info.split("|")
            if part.strip().split(":")[0].strip() in GPU_BACKENDS]
    return [*dict.fromkeys(gpus or ["GPU"]), "CPU"]


# llama.cpp's GPU back ends, as its system info names them.
GPU_BACKENDS = {"CUDA", "Metal", "Vulkan", "SYCL", "HIP", "ROCm", "MUSA", "CANN", "OpenCL"}


class LlamaModel:
    def __init__(self, settings: LlamaSettings) -> None:
        self.settings = settings
        self.renderer = PromptRenderer(settings.template)
        self.gate = GenerationGate(settings.max_waiting, settings.wait_timeout_s)
        self.stats = GenerationStats()
        self._llm: Any = None
        self._is_end: Callable[[int], bool] = lambda token: False
        self._vocab: Any = None
        self._runtime = "llama.cpp"
        self._devices = ["CPU"]

    def load(self) -> None:
        s = self.settings
        # OpenMP reads this when llama.cpp's library loads: spinning threads would steal
        # the second core from the other services on a 2-core machine.
        os.environ.setdefault("OMP_WAIT_POLICY", s.omp_wait_policy)
        import llama_cpp

        self._devices = llama_devices(llama_cpp, s.gpu_layers)
        llm = llama_cpp.Llama(
            model_path=str(s.path), n_ctx=s.n_ctx, n_batch=s.n_batch, n_ubatch=s.n_batch,
            n_threads=s.threads, n_threads_batch=s.threads,
            n_gpu_layers=s.gpu_layers if self._devices[0] != "CPU" else 0, verbose=False)
        vocab = llama_cpp.llama_model_get_vocab(llm.model)
        self._is_end = lambda token: bool(llama_cpp.llama_vocab_is_eog(vocab, token))
        self._vocab = vocab
        self._runtime = f"llama.cpp (llama-cpp-python {llama_cpp.__version__})"
        self._llm = llm
        self._warm_up()
        log.info("%s loaded on %s: context %d tokens, %d thread(s), prompt prefix %d tokens",
                 s.catalog_name, self._devices[0], s.n_ctx, s.threads,
                 len(self._tokenize(self.renderer.prefix)))

    def _warm_up(self) -> None:
        """One short generation: evaluates the fixed prompt prefix so it is cached."""
        examples = self.settings.template.examples
        question = examples[0].question if examples else "Hello"
        for _ in self.generate(GenerationRequest(question, max_tokens=2), lambda: None):
            pass
        self.stats = GenerationStats()

    def close(self) -> None:
        # Callers are cancelled by the server's shutdown, so a running generation ends
        # within a token; freeing the weights under it would crash the process.
        if not self.gate.close(CLOSE_WAIT_S):
            log.warning("a generation is still running after %.0f s; weights left to the OS",
                        CLOSE_WAIT_S)
            return
        llm, self._llm = self._llm, None
        if llm is not None:
            llm.close()

    def info(self) -> ModelInfo:
        s = self.settings
        return ModelInfo(
            model=s.catalog_name, runtime=self._runtime, providers=list(self._devices),
            license=s.license, sha256=s.sha256,
            parameters={"n_ctx": str(s.n_ctx), "threads": str(s.threads),
                        "gpu_layers": str(s.gpu_layers),
                        "prompt": s.prompt_file, "temperature": str(s.sampling.temperature),
                        "reuse_prefix": str(s.reuse_prefix).lower(),
                        "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY", "")})

    @property
    def loaded(self) -> bool:
        return self._llm is not None

    def generate(self, request: GenerationRequest, still_wanted: StillWanted) -> Iterator[Chunk]:
        """Text chunks as they are produced; the last one carries `finished`.

        Raises InvalidInput (prompt does not fit), Overloaded (queue full or wait too long),
        or whatever still_wanted raises.
        """
        started = time.perf_counter()
        llm = self._require_loaded()
        self._refuse_control_text(
            [request.prompt, request.system, *(text for turn in request.history for text in turn),
             *(f.value for f in request.facts if isinstance(f.value, str))])
        rendered = self.renderer.render(request.prompt, request.facts, request.system,
                                        request.history)
        grammar = json_grammar(request.json, self._vocab) if request.json is not None else None
        tokens = self._tokenize(rendered.text, add_bos=True)
        self._check_fits(len(tokens), request.max_tokens)
        log.debug("prompt facts: %s", rendered.facts)
        prepared = time.perf_counter()
        with self.gate.turn(still_wanted) as waited_s:
            finished = yield from self._run(llm, tokens, request, still_wanted,
                                            (started, prepared, waited_s), grammar)
        # The model is free before the last chunk goes out, whatever the consumer does next.
        yield Chunk("", finished)

    def _run(self, llm: Any, tokens: list[int], request: GenerationRequest,
             still_wanted: StillWanted, marks: tuple[float, float, float], grammar: Any
             ) -> Generator[Chunk, None, Finished]:
        started, prepared, waited_s = marks
        acquired = time.perf_counter()
        if not self.settings.reuse_prefix:
            llm.reset()
        cached = self._cached_prefix(llm, tokens)
        result = LoopResult()
        sampling = replace(self.settings.sampling, temperature=request.temperature)
        if request.top_p is not None:
            sampling = replace(sampling, top_p=request.top_p)
        if request.seed is not None:
            llm.set_seed(request.seed)
        # JSON ends where its grammar does: the format's stops (a newline) would cut it.
        stops = [*([] if grammar else self.renderer.stop), *request.stop]
        # A consumer that stops reading (a streaming client gone between chunks) closes
        # this generator at its yield: nothing more is generated, and it is recorded.
        reason = ABANDONED
        try:
            for text in run_tokens(llm, tokens, sampling, request.max_tokens, stops,
                                   self._is_end, still_wanted, result, time.perf_counter,
                                   grammar):
                yield Chunk(text)
            reason = result.finish_reason
        except OricfError as exc:
            reason = type(exc).__name__
            log.info("generation stopped after %d token(s): %s", result.completion_tokens, exc)
            raise
        finally:
            self._record(len(tokens), cached, result, reason)
        ended = time.perf_counter()
        first = result.first_token_at if result.first_token_at is not None else ended
        return Finished(
            finish_reason=result.finish_reason, prompt_tokens=len(tokens),
            completion_tokens=result.completion_tokens, cached_tokens=cached,
            queue_ms=waited_s * 1e3, preprocess_ms=_ms(started, prepared),
            first_token_ms=_ms(started, first), inference_ms=_ms(acquired, ended),
            total_ms=_ms(started, ended))

    def _record(self, prompt_tokens: int, cached: int, result: LoopResult, reason: str) -> None:
        stats = self.stats
        stats.generations += 1
        stats.completion_tokens += result.completion_tokens
        stats.last_finish_reason = reason
        stats.last_completion_tokens = result.completion_tokens
        stats.last_cached_tokens = cached
        stats.last_prompt_tokens = prompt_tokens
        if reason not in ("stop", "length"):
            stats.stopped_early += 1

    def _require_loaded(self) -> Any:
        if self._llm is None:
            raise NotReady("the language model is not loaded")
        return self._llm

    def _tokenize(self, text: str, add_bos: bool = False, special: bool = True) -> list[int]:
        tokens: list[int] = self._require_loaded().tokenize(
            text.encode("utf-8"), add_bos=add_bos, special=special)
        return tokens

    def _refuse_control_text(self, texts: Sequence[str]) -> None:
        """Caller text must not smuggle in the model's control tokens (e.g. <end_of_turn>)."""
        for text in texts:
            if self._tokenize(text, special=True) != self._tokenize(text, special=False):
                raise InvalidInput("the prompt or a fact's text contains the model's control "
                                   "token text (such as <end_of_turn> or <|im_end|>)")

    def _check_fits(self, prompt_tokens: int, max_tokens: int) -> None:
        n_ctx = self.settings.n_ctx
        if prompt_tokens + max_tokens > n_ctx:
            raise InvalidInput(
                f"the prompt ({prompt_tokens} tokens with the template) plus max_tokens "
                f"({max_tokens}) exceeds the model's context window of {n_ctx} tokens; "
                f"shorten the prompt or the facts, or ask for fewer tokens")

    @staticmethod
    def _cached_prefix(llm: Any, tokens: list[int]) -> int:
        """How many leading prompt tokens llama.cpp can take from its KV cache."""
        previous = llm.input_ids[:llm.n_tokens].tolist()
        same = 0
        for a, b in zip(previous, tokens, strict=False):
            if a != b:
                break
            same += 1
        # llama.cpp re-evaluates at least the last prompt token to get fresh logits.
        return min(same, len(tokens) - 1)
