"""The demo's spoken answers: the gateway speaks each answer onto a topic, and the demo plays
it on this machine's default audio device and/or writes it into a WAV file.

The deployment's pipeline gains, by an overlay: `sentences: true` on the routes that answer
on /answer, each sentence as the data product `answer_sentence`, and a `voice` route that
synthesizes each sentence on the speech synthesis service (started by the demo, on a free
loopback port, if neither the deployment nor the pipeline has one) and publishes its audio
on /answer/audio in the project's audio convention (std_msgs/Int16MultiArray, 16 kHz mono).
The robot speaks a sentence while it is still generating the next, and the demo hears it as
it comes.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from oricf.errors import ConfigError
from oricf.gateway.config import PipelineConfig, load_pipeline
from oricf.gateway.speaking import Speaking
from oricf.gateway.values import AudioClip
from oricf.launch.deployment import Deployment, LocalService

log = logging.getLogger(__name__)

AUDIO_TOPIC = "/answer/audio"
ANSWER_TOPIC = "/answer"
TOPIC_RATE = 16000


def voice_overlay(pipeline: PipelineConfig, tts: str | None) -> dict[str, Any]:
    """The pipeline overlay that speaks every answer published on /answer; `tts` is the
    address of the service the demo starts (None: the pipeline's `tts` endpoint)."""
    routes: dict[str, Any] = {}
    for name, route in pipeline.routes.items():
        if route.call.method != "Generate" or not any(
                o.topic == ANSWER_TOPIC for o in route.outputs):
            continue
        outputs = [o.model_dump(by_alias=True, exclude_none=True) for o in route.outputs]
        outputs.append({"product": "answer_sentence", "from": "sentence", "max_age_s": 30})
        routes[name] = {"call": {"sentences": True}, "outputs": outputs}
    if not routes:
        raise ConfigError(f"{pipeline.origin}: no route answers on {ANSWER_TOPIC} to speak")
    routes["voice"] = {
        "input": {"product": "answer_sentence"},
        "call": {"service": "tts", "method": "Synthesize", "text": "{value}"},
        "outputs": [{"topic": AUDIO_TOPIC, "type": "std_msgs/Int16MultiArray",
                     "from": "speech"}]}
    overlay: dict[str, Any] = {"routes": routes}
    if tts is not None:
        overlay["endpoints"] = {"tts": {"address": tts, "deadline_ms": 10000}}
    return overlay


def speaking_deployment(deployment: Deployment, overlay_file: Path) -> Deployment:
    """The deployment with the voice overlay on its gateway (written to overlay_file), and
    the speech synthesis service among those it starts."""
    import yaml

    gateway = deployment.gateway
    assert gateway is not None
    from oricf.launch.health import free_port

    pipeline = load_pipeline(gateway.config, gateway.overlays)
    services = dict(deployment.services)
    tts = None
    if "tts" not in services and "tts" not in pipeline.endpoints:
        tts = f"127.0.0.1:{free_port()}"
        services["tts"] = LocalService(listen=tts)
    elif "tts" not in pipeline.endpoints:  # the deployment's service, wired at its address
        tts = services["tts"].listen or "127.0.0.1:50054"
    overlay_file.write_text(yaml.safe_dump(voice_overlay(pipeline, tts)))
    gateway = gateway.model_copy(update={"overlays": [*gateway.overlays, overlay_file]})
    return deployment.model_copy(update={"gateway": gateway, "services": services})


class AnswerPlayer:
    """Plays the answers' audio on the default output device (when there is one) and/or
    appends it to a WAV file."""

    def __init__(self, play: bool, wav: Path | None) -> None:
        self.speaker: Any = None
        self.wav: Any = None
        self.note = ""
        if play:
            from oricf.gateway.sinks.speaker_sink import Speaker

            try:
                self.speaker = Speaker("default", Speaking())
            except ConfigError as exc:
                self.note = f"not played: {exc}"
        if wav is not None:
            from oricf.gateway.sinks.wav import WavFiles

            self.wav = WavFiles()
            self._path = str(wav)

    def play(self, samples: Any) -> None:
        clip = AudioClip(np.asarray(samples, dtype="<i2").tobytes(), TOPIC_RATE, 1)
        if self.speaker is not None:
            self.speaker.play(clip)
        if self.wav is not None:
            self.wav.write(self._path, clip)

    def first_sample_after(self, moment: float, timeout: float) -> float | None:
        """When the speaker's first stream since `moment` began to sound."""
        if self.speaker is None:
            return None
        import time

        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            starts = [s for s in self.speaker.stats.starts if s >= moment]
            if starts:
                return float(starts[0])
            time.sleep(0.01)
        return None

    def wait_played(self, timeout: float) -> None:
        if self.speaker is not None:
            self.speaker.idle(timeout)

    def close(self) -> None:
        if self.speaker is not None:
            self.speaker.close()
        if self.wav is not None:
            self.wav.close()
