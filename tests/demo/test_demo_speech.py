"""`oricf demo` speaks its answers: the real services (speech synthesis included), the real
gateway and DDS, and a PulseAudio server whose default sink is a null sink, standing in for
the machine's speaker; what the demo played is recorded from the sink's monitor and
transcribed, and --speak-to's WAV file holds the same speech."""

from __future__ import annotations

import logging
import re
import wave

import numpy as np

from tests.demo.spoken import DemoRun
from tests.demo.test_demo import reported
from tests.gateway.sinks.voice import spoken_words, voiced, word_errors
from tests.support.services import RunningService

log = logging.getLogger(__name__)


def test_the_demo_plays_each_answer_and_writes_it(spoken_demo: DemoRun,
                                                  asr: RunningService) -> None:
    code, command = spoken_demo.code, spoken_demo.command
    played, wav = spoken_demo.played, spoken_demo.wav
    output = command.output
    log.info("%s", output)
    assert code == 0, output
    _, answer = reported(output)
    first_audio = re.search(r"spoken     : first audio (\d+) ms after the question, "
                            r"([\d.]+) s of speech", output)
    assert first_audio, output
    assert "median first audio" in output
    with wave.open(str(wav)) as spoken:
        written = np.frombuffer(spoken.readframes(spoken.getnframes()), "<i2")
        assert spoken.getframerate() == 16000
    assert abs(len(written) / 16000 - float(first_audio.group(2))) < 0.05
    from tests.gateway.sinks.voice import transcribe

    sounded = voiced(played)
    assert len(sounded), "nothing was played"
    heard_played = transcribe(asr.channel, played[max(sounded[0] - 8000, 0):
                                                  sounded[-1] + 8000])
    heard_written = transcribe(asr.channel, written)
    reference = spoken_words(answer)
    for heard in (heard_played, heard_written):
        assert word_errors(reference, spoken_words(heard)) / len(reference) <= 0.25, \
            (answer, heard_played, heard_written)
