"""`say` over MCP: the text goes to the pipeline's speech route, the real speech synthesizer
speaks it, and the audio lands where the pipeline sends it (a WAV file here); recognised
again by the real speech recogniser, it says what was asked."""

from __future__ import annotations

import time
from pathlib import Path

import anyio
import yaml

from oricf.audio.wav import parse_wav
from tests.gateway.agents.session import stdio_session, text_of
from tests.support.processes import free_port
from tests.support.services import RunningService
from tests.support.speech import words


def test_say_speaks_through_the_pipeline(tts: RunningService,
                                         tmp_path: Path, asr: RunningService) -> None:
    wav = tmp_path / "spoken.wav"
    config = tmp_path / "voice.yaml"
    config.write_text(yaml.safe_dump({
        "endpoints": {"tts": {"address": tts.address, "deadline_ms": 30000}},
        "channels": {"typed": {"listen": f"127.0.0.1:{free_port()}"}},
        "routes": {"voice": {"input": {"text": "typed"},
                             "call": {"service": "tts", "method": "Synthesize",
                                      "text": "{text}"},
                             "outputs": [{"wav": str(wav), "from": "speech"}]}}}))

    async def scenario() -> None:
        async with stdio_session("--config", str(config)) as session:
            said = await session.call_tool("say", {"text": "The hallway is clear."})
            assert not said.is_error, text_of(said)
            deadline = time.monotonic() + 60
            while not wav.exists() or wav.stat().st_size < 16000:
                assert time.monotonic() < deadline, "nothing was spoken"
                await anyio.sleep(0.5)
            await anyio.sleep(1.0)  # the rest of the sentence

    anyio.run(scenario)
    audio = parse_wav(wav.read_bytes())
    assert audio.samples.shape[0] / audio.sample_rate > 0.5
    from oricf.v1 import speech_pb2, speech_pb2_grpc

    heard = speech_pb2_grpc.SpeechRecognizerStub(asr.channel).Transcribe(
        speech_pb2.TranscribeRequest(audio=speech_pb2.Audio(
            data=audio.samples.astype("<i2").tobytes(), encoding="pcm_s16le",
            sample_rate=audio.sample_rate, channels=audio.channels), language="en"),
        timeout=60)
    assert {"hallway", "clear"} <= set(words(heard.text)), heard.text
