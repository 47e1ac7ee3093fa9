"""What one request may cost the speech synthesis service, against real `oricf serve tts
--http-listen` processes of their own with both shipped voices: text whose numbers write out
many times longer, a script the voices spell out letter by letter (300 Arabic characters are
140 s of "Arabic mim, Arabic alef..."), digits at a quarter of the speed, text that makes
more audio than audio.max_audio_s, and clients that abandon a stream (HTTP) or cancel it
(gRPC). Each is refused with a 400 / INVALID_ARGUMENT naming its limit, or made in runs of
bounded size; the process's peak resident memory (VmHWM) and its CPU time (/proc/PID/stat)
grow by bounded amounts, and a normal request is still answered with speech."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import grpc
import httpx
import numpy as np
import pytest

from oricf.v1 import synthesis_pb2, synthesis_pb2_grpc
from tests.support.openai_http import HttpService, http_service, overlay
from tests.support.peak_memory import memory_kb
from tests.support.services import CHANNEL_OPTIONS
from tests.support.tts import VOICES

T = TypeVar("T")

RATE = 22050
ARABIC = ("مرحبا بك في الروبوت " * 16)[:300]
NUMBERS = "1" + ",000" * 400     # 1,601 characters; 6,000 once read digit by digit
DIGITS = "1234567890" * 6        # 60 digits, read one by one
LONG = " ".join(["This sentence goes on and on for a long while, without a pause and without "
                 "an end, so that the voice has many words to say before it can stop."] * 8)
# A run of the Piper voice holds about 20-35 MB per second of its audio, and runs are at
# most max_run_phonemes (200) long at speed 1 (12-14 s of audio), fewer in proportion when
# slower: a run of the Arabic text peaks at 400-460 MB here, of the digits at a quarter of
# the speed (50 phonemes) at about 270 MB. Made in one run, the Arabic text's first sentence
# took 1.4 GB, the digits' 610 MB. espeak-ng runs in a process of its own.
COSTLY = {"arabic-joe": (ARABIC, "joe", 1.0, 650), "arabic-espeak": (ARABIC, "espeak", 1.0, 100),
          "digits-joe": (DIGITS, "joe", 0.25, 450),
          "digits-espeak": (DIGITS, "espeak", 0.25, 100)}
# An abandoned stream (HTTP, or a cancelled gRPC call) finishes the run in progress (at most
# about 2 s of CPU here), then stops; before, it finished the sentence in progress (6-7 s of
# CPU at speed 0.25).
MAX_CPU_AFTER_LEAVING_S = 4.0
IDLE_CPU_S = 0.05   # over IDLE_WINDOW_S: the service has stopped working
IDLE_WINDOW_S = 0.5
SHORT_AUDIO_S = 20  # audio.max_audio_s of the second service


def cpu_s(pid: int) -> float:
    """CPU time of the process, its threads and its waited-for children (espeak-ng)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    utime, stime, cutime, cstime = (int(f) for f in fields[11:15])
    return (utime + stime + cutime + cstime) / os.sysconf("SC_CLK_TCK")


def peak_growth_mb(service: HttpService, send: Callable[[], T]) -> tuple[T, float]:
    """send()'s result, and how far above its resident memory before the call the service's
    peak went meanwhile (writing 5 to clear_refs resets a process's peak to its current
    resident memory)."""
    pid = service.process.pid
    Path(f"/proc/{pid}/clear_refs").write_text("5")
    before = memory_kb(pid, "VmRSS")
    result = send()
    return result, (memory_kb(pid, "VmHWM") - before) / 1024


def wait_idle(service: HttpService, deadline_s: float = 60) -> float:
    """The process's CPU time once it has stopped working (under IDLE_CPU_S in a window)."""
    deadline = time.monotonic() + deadline_s
    last = cpu_s(service.process.pid)
    while time.monotonic() < deadline:
        time.sleep(IDLE_WINDOW_S)
        now = cpu_s(service.process.pid)
        if now - last < IDLE_CPU_S:
            return now
        last = now
    raise AssertionError(f"the service was still working after {deadline_s} s")


def speak(service: HttpService, text: str, voice: str = "joe", **fields: Any
          ) -> httpx.Response:
    return httpx.post(f"{service.base_url}/v1/audio/speech", timeout=300,
                      json={"input": text, "voice": voice, "response_format": "pcm", **fields})


def seconds(response: httpx.Response) -> float:
    return len(response.content) / 2 / RATE


def still_speaks(service: HttpService) -> None:
    for voice in VOICES:
        response = speak(service, "I can see four people in the room.", voice)
        assert response.status_code == 200, response.text
        assert 1.0 < seconds(response) < 5.0
        level = np.sqrt(np.mean(np.frombuffer(response.content, "<i2").astype(float) ** 2))
        assert level > 300  # speech, not silence


@pytest.fixture(scope="module")
def warm_tts(tts_http: HttpService) -> HttpService:
    """The session's tts_http (its shipped limits) once each voice has spoken: their first
    runs allocate for good, so what a test measures is its own request's cost."""
    still_speaks(tts_http)
    return tts_http


@pytest.fixture(scope="module")
def tts_short(tmp_path_factory: pytest.TempPathFactory) -> Iterator[HttpService]:
    """The service with audio.max_audio_s lowered, so that going past it is quick."""
    folder = tmp_path_factory.mktemp("tts-short")
    short = overlay(folder, {"audio": {"max_audio_s": SHORT_AUDIO_S}})
    with http_service("tts", "--overlay", short) as service:
        yield service


@pytest.mark.parametrize("voice", VOICES)
def test_numbers_that_write_out_too_long_are_refused_before_synthesis(
        warm_tts: HttpService, voice: str) -> None:
    used = cpu_s(warm_tts.process.pid)
    response = speak(warm_tts, NUMBERS, voice)
    assert response.status_code == 400, response.status_code
    error = response.json()["error"]
    assert error["param"] == "input"
    assert error["message"].startswith("input: 6,003 characters once numbers")
    assert error["message"].endswith("limit of 4,000 (text.max_spoken_chars)")
    assert wait_idle(warm_tts) - used < 1.0


# The neural voice's Arabic run is the long run's; its digits run stays in the default run.
@pytest.mark.parametrize(("text", "voice", "speed", "max_growth_mb"), [
    pytest.param(*values, id=name, marks=[pytest.mark.long] if name == "arabic-joe" else [])
    for name, values in COSTLY.items()])
def test_costly_sentences_are_made_in_runs_of_bounded_memory(
        warm_tts: HttpService, text: str, voice: str, speed: float, max_growth_mb: float) -> None:
    response, growth = peak_growth_mb(warm_tts, lambda: speak(warm_tts, text, voice, speed=speed))
    assert response.status_code == 200, response.text
    assert seconds(response) > 30  # all of it was said
    assert growth < max_growth_mb, f"peak resident memory grew by {growth:.0f} MiB"
    still_speaks(warm_tts)


@pytest.mark.parametrize("voice", VOICES)
def test_an_abandoned_stream_stops_its_synthesis(warm_tts: HttpService, voice: str) -> None:
    wait_idle(warm_tts)
    with httpx.stream("POST", f"{warm_tts.base_url}/v1/audio/speech", timeout=120,
                      json={"input": LONG, "voice": voice, "speed": 0.25,
                            "response_format": "pcm"}) as response:
        assert response.status_code == 200
        next(response.iter_raw())  # the first sentence has come
        left = cpu_s(warm_tts.process.pid)
    after = wait_idle(warm_tts) - left
    assert after < MAX_CPU_AFTER_LEAVING_S, f"{after:.1f} s of CPU after the client left"
    still_speaks(warm_tts)


def test_audio_past_the_limit_is_refused_over_http(tts_short: HttpService) -> None:
    # One sentence of 80 s: past the limit before the answer starts.
    response = speak(tts_short, ARABIC, "espeak")
    assert response.status_code == 400, response.status_code
    error = response.json()["error"]
    assert error["param"] == "input"
    assert error["message"] == (f"input: at speed 1 it makes more than {SHORT_AUDIO_S} s of "
                                f"audio, this service's limit (audio.max_audio_s); send "
                                f"less text or a higher speed")


@pytest.mark.parametrize("voice", VOICES)
def test_audio_past_the_limit_stops_synthesis_over_grpc(tts_short: HttpService,
                                                        voice: str) -> None:
    text = " ".join(f"This is sentence number {i}." for i in range(40))  # about 60 s
    request = synthesis_pb2.SynthesizeRequest(text=text, voice=voice)
    with grpc.insecure_channel(tts_short.grpc_address, options=CHANNEL_OPTIONS) as channel:
        stub = synthesis_pb2_grpc.SpeechSynthesizerStub(channel)
        with pytest.raises(grpc.RpcError) as refused:
            stub.Synthesize(request, timeout=120)
        assert refused.value.code() == grpc.StatusCode.INVALID_ARGUMENT
        assert "(audio.max_audio_s)" in (refused.value.details() or "")
        sent = 0.0
        with pytest.raises(grpc.RpcError) as cut:
            for message in stub.SynthesizeStream(request, timeout=120):
                sent += message.duration_s
        assert cut.value.code() == grpc.StatusCode.INVALID_ARGUMENT
        assert "(audio.max_audio_s)" in (cut.value.details() or "")
        assert 0 < sent <= SHORT_AUDIO_S
    still_speaks(tts_short)


@pytest.mark.parametrize("voice", VOICES)
def test_a_cancelled_grpc_stream_stops_its_synthesis(warm_tts: HttpService, voice: str) -> None:
    wait_idle(warm_tts)
    request = synthesis_pb2.SynthesizeRequest(text=LONG, voice=voice, speed=0.25)
    with grpc.insecure_channel(warm_tts.grpc_address, options=CHANNEL_OPTIONS) as channel:
        call = synthesis_pb2_grpc.SpeechSynthesizerStub(channel).SynthesizeStream(
            request, timeout=120)
        assert next(call).sentence == 0
        call.cancel()
        left = cpu_s(warm_tts.process.pid)
        after = wait_idle(warm_tts) - left
    assert after < MAX_CPU_AFTER_LEAVING_S, f"{after:.1f} s of CPU after the call was cancelled"
    still_speaks(warm_tts)
