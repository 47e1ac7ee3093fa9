"""An OpenAI-compatible server as an endpoint's target (Ollama, vLLM, llama.cpp's server,
LocalAI, ORICF's own services with --http-listen), through the official `openai` client.

Failures become CallFailed, a grpc.RpcError with the status code that means the same, so
that deadlines, retries, failover and the routes' error counts treat both protocols alike:

    connection refused or reset     UNAVAILABLE          fail over
    timed out                       DEADLINE_EXCEEDED    fail over
    429                             RESOURCE_EXHAUSTED   retry after Retry-After or backoff
    503                             UNAVAILABLE          retry after Retry-After, else fail over
    400, 413, 422                   INVALID_ARGUMENT
    401 / 403 / 404                 UNAUTHENTICATED / PERMISSION_DENIED / NOT_FOUND
    other 5xx                       INTERNAL

The client never retries by itself (the endpoint does), and the token goes only in the
Authorization header: it is never logged, nor part of any error text.
"""

from __future__ import annotations

import contextlib
import email.utils
import ssl
import time
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import grpc

from oricf.errors import ConfigError
from oricf.gateway.endpoints.config import TargetConfig
from oricf.tracing import inject

if TYPE_CHECKING:
    import httpx

STATUS_CODES = {
    400: grpc.StatusCode.INVALID_ARGUMENT, 401: grpc.StatusCode.UNAUTHENTICATED,
    403: grpc.StatusCode.PERMISSION_DENIED, 404: grpc.StatusCode.NOT_FOUND,
    413: grpc.StatusCode.INVALID_ARGUMENT, 422: grpc.StatusCode.INVALID_ARGUMENT,
    429: grpc.StatusCode.RESOURCE_EXHAUSTED, 503: grpc.StatusCode.UNAVAILABLE,
    504: grpc.StatusCode.DEADLINE_EXCEEDED,
}
MAX_DETAIL_CHARS = 300  # of a server's error message, in logs


class CallFailed(grpc.RpcError):
    """An HTTP call that failed, told as gRPC tells it: code(), details(), and the server's
    Retry-After as grpc-retry-pushback-ms in trailing_metadata()."""

    def __init__(self, code: grpc.StatusCode, details: str, retry_after_ms: float = 0) -> None:
        super().__init__(details)
        self._code = code
        self._details = details
        self._retry_after_ms = retry_after_ms

    def code(self) -> grpc.StatusCode:
        return self._code

    def details(self) -> str:
        return self._details

    def trailing_metadata(self) -> tuple[tuple[str, str], ...]:
        if not self._retry_after_ms:
            return ()
        return (("grpc-retry-pushback-ms", str(int(self._retry_after_ms))),)


def retry_after_ms(value: str | None) -> float:
    """Retry-After as milliseconds: delta-seconds or an HTTP date; 0 if absent or unreadable."""
    if not value:
        return 0.0
    try:
        return max(0.0, float(value) * 1000)
    except ValueError:
        pass
    try:
        when = email.utils.parsedate_to_datetime(value).timestamp()
    except (TypeError, ValueError):
        return 0.0
    return max(0.0, (when - time.time()) * 1000)


@contextlib.contextmanager
def as_grpc_errors() -> Iterator[None]:
    import openai

    try:
        yield
    except openai.APITimeoutError:
        raise CallFailed(grpc.StatusCode.DEADLINE_EXCEEDED, "timed out") from None
    except openai.APIConnectionError as exc:
        raise CallFailed(grpc.StatusCode.UNAVAILABLE, f"cannot connect: {exc}") from None
    except openai.APIStatusError as exc:
        status = exc.status_code
        code = STATUS_CODES.get(status, grpc.StatusCode.INTERNAL if status >= 500
                                else grpc.StatusCode.UNKNOWN)
        wait = retry_after_ms(exc.response.headers.get("retry-after"))
        message = str(exc.message)[:MAX_DETAIL_CHARS]
        raise CallFailed(code, f"HTTP {status}: {message}", wait) from None


class OpenAITarget:
    protocol = "openai"

    def __init__(self, config: TargetConfig) -> None:
        import openai

        assert config.model is not None  # the schema requires it
        self.address = config.address
        self.model = config.model
        token = config.token.tokens()[0] if config.token else "none"
        # Each request carries the route's trace context while tracing is on.
        hooks = {"request": [_trace_context]}
        http_client = (openai.DefaultHttpxClient(verify=_ssl_context(config), event_hooks=hooks)
                       if config.tls is not None else openai.DefaultHttpxClient(event_hooks=hooks))
        self.client = openai.OpenAI(base_url=config.address, api_key=token, max_retries=0,
                                    http_client=http_client)

    def serving(self, timeout: float = 1.0) -> bool:
        """Ready when GET /models answers (what Ollama, vLLM and llama.cpp's server all do)."""
        try:
            with as_grpc_errors():
                self.client.models.list(timeout=timeout)
            return True
        except CallFailed:
            return False

    def close(self) -> None:
        self.client.close()


def _trace_context(request: httpx.Request) -> None:
    """An httpx request hook, run in the calling thread: the route's call span is current."""
    for name, value in inject(()):
        request.headers[name] = value


def _ssl_context(config: TargetConfig) -> ssl.SSLContext:
    tls = config.tls
    assert tls is not None
    # The ssl module reads the certificate and key by name: each is read first as the
    # gRPC channel reads it, so a FIFO or a device is refused rather than waited on.
    ca, _, _ = tls.files("tls")
    try:
        context = ssl.create_default_context(cadata=ca.decode("ascii", "replace"))
        if tls.cert is not None and tls.key is not None:
            context.load_cert_chain(str(tls.cert), str(tls.key))
    except (OSError, ssl.SSLError) as exc:
        raise ConfigError(f"tls: cannot load {tls.ca}, {tls.cert} or {tls.key}: {exc}"
                          ) from None
    return context


def chat_completion(target: OpenAITarget, body: dict[str, Any], timeout: float,
                    stream: bool) -> str:
    """The answer of one chat completion; streamed, its pieces joined as they come."""
    with as_grpc_errors():
        if not stream:
            reply = target.client.chat.completions.create(
                model=target.model, timeout=timeout, **body)
            return reply.choices[0].message.content or "" if reply.choices else ""
        pieces = []
        for chunk in target.client.chat.completions.create(
                model=target.model, timeout=timeout, stream=True, **body):
            if chunk.choices and chunk.choices[0].delta.content:
                pieces.append(chunk.choices[0].delta.content)
        return "".join(pieces)


def transcription(target: OpenAITarget, wav: bytes, language: str, timeout: float) -> str:
    """The text of one utterance (a WAV file) by POST /audio/transcriptions."""
    import openai

    with as_grpc_errors():
        reply = target.client.audio.transcriptions.create(
            model=target.model, file=("utterance.wav", wav, "audio/wav"),
            response_format="json", language=language or openai.omit, timeout=timeout)
    return str(reply.text)
