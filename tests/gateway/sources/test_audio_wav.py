"""WAV files as audio inputs: espeak-ng questions (sox-converted) cut into utterances by the
real Silero VAD and transcribed by the real ASR service through the gateway; files that are
no WAV, cut short, or of another sample format; the `asr` extra missing; the schema."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
import yaml

from oricf.audio import encode_wav, synthesize
from oricf.errors import ConfigError
from oricf.gateway.config import InputConfig, load_pipeline
from oricf.gateway.sources.audio_source import AudioSource
from oricf.gateway.values import AudioClip
from tests.gateway.sources.audio import gateway
from tests.support.services import RunningService
from tests.support.speech import QUESTION, QUESTION_WORDS, words

SECOND_QUESTION = "What is in front of you"


@pytest.fixture(scope="module")
def questions(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two spoken questions a second apart: espeak-ng, then sox to 16 kHz mono."""
    gap = np.zeros(16000, dtype=np.int16)
    samples = np.concatenate([gap[:4000], synthesize(QUESTION), gap,
                              synthesize(SECOND_QUESTION), gap[:8000]])
    path = tmp_path_factory.mktemp("wav") / "questions.wav"
    path.write_bytes(encode_wav(samples, 16000))
    return path


def cut(path: Path | str) -> list[AudioClip]:
    """The utterances an audio source sends for a file, once the file has ended."""
    clips: list[AudioClip] = []
    ended = threading.Event()
    source = AudioSource("mic", InputConfig(audio=str(path)),
                         lambda load: clips.append(load()["audio"]), lambda route: ended.set())
    source.start()
    assert ended.wait(60)
    return clips


def test_questions_in_a_wav_file_are_transcribed_and_the_route_ends_without_ros(
        questions: Path, tmp_path: Path, asr: RunningService) -> None:
    no_ros = tmp_path / "no_ros" / "rclpy"
    no_ros.mkdir(parents=True)
    (no_ros / "__init__.py").write_text("raise ImportError('rclpy must not be imported')\n")
    (tmp_path / "questions.wav").write_bytes(questions.read_bytes())
    config = tmp_path / "wav.yaml"
    config.write_text(yaml.safe_dump({
        "endpoints": {"asr": {"address": asr.address, "deadline_ms": 10000}},
        "routes": {"speech": {
            "input": {"audio": "questions.wav"},  # beside the YAML file
            "call": {"service": "asr", "method": "Transcribe", "language": "en"},
            "outputs": [{"jsonl": "-", "from": "transcript"}]}}}))
    env = {"PYTHONPATH": str(no_ros.parent), "PATH": "/usr/bin:/bin",
           "HOME": str(Path.home())}
    with gateway(["--config", str(config)], env) as running:
        assert running.process.wait(timeout=120) == 0, running.stderr
    heard = [running.lines.get(timeout=5)["transcript"] for _ in range(2)]
    assert set(QUESTION_WORDS) <= set(words(heard[0])), heard
    assert {"what", "front", "you"} <= set(words(heard[1])), heard
    assert "questions.wav ended after 2 utterance(s); the route ends" in running.stderr


def test_any_rate_and_channels_become_16_khz_mono_utterances(questions: Path,
                                                            tmp_path: Path) -> None:
    stereo = tmp_path / "questions-44k-stereo.wav"
    subprocess.run(["sox", "-R", str(questions), "-r", "44100", "-c", "2", str(stereo)], check=True)
    clips = cut(stereo)
    assert [(c.sample_rate, c.channels) for c in clips] == [(16000, 1), (16000, 1)]
    assert [c.duration_s for c in clips] == pytest.approx(
        [c.duration_s for c in cut(questions)], abs=0.07)
    assert all(1.0 < c.duration_s < 3.0 for c in clips)


def test_a_wav_file_cut_short_is_read_as_far_as_it_goes(questions: Path, tmp_path: Path,
                                                       caplog: pytest.LogCaptureFixture) -> None:
    data = questions.read_bytes()
    short = tmp_path / "short.wav"
    short.write_bytes(data[:len(data) // 2 + 1])  # inside the second question, mid-sample
    clips = cut(short)
    assert len(clips) >= 1
    assert "of the" in caplog.text and "frames its header declares (truncated?)" in caplog.text


@pytest.mark.parametrize(("content", "problem"), [
    (b"hello, this is text", "not a WAV file that can be read (file does not start with RIFF"),
    (b"", "not a WAV file (it ends inside its header: empty or truncated)"),
    ("header", "not a WAV file (it ends inside its header: empty or truncated)"),
    ("8-bit", "8-bit samples; only 16-bit PCM is read"),
    ("float", "not a WAV file that can be read (unknown format: 3)"),
])
def test_a_file_that_is_no_usable_wav_is_refused_at_start(
        questions: Path, tmp_path: Path, content: bytes | str, problem: str) -> None:
    path = tmp_path / "bad.wav"
    if content == "header":
        path.write_bytes(questions.read_bytes()[:30])
    elif isinstance(content, str):
        encoding = ["-b", "8"] if content == "8-bit" else ["-e", "floating-point", "-b", "32"]
        subprocess.run(["sox", "-R", str(questions), *encoding, str(path)], check=True)
    else:
        path.write_bytes(content)
    with pytest.raises(ConfigError) as error:
        AudioSource("mic", InputConfig(audio=str(path)), lambda load: None, lambda route: None)
    assert str(error.value).startswith(f"routes.mic.input.audio: {path}: {problem}")


def test_a_missing_or_bad_wav_file_stops_the_gateway_at_start(tmp_path: Path) -> None:
    (tmp_path / "notes.wav").write_text("not audio")
    config = tmp_path / "wav.yaml"
    config.write_text(yaml.safe_dump({
        "endpoints": {"asr": {"address": "127.0.0.1:1"}},
        "routes": {"speech": {"input": {"audio": "notes.wav"},
                              "call": {"service": "asr", "method": "Transcribe"},
                              "outputs": [{"jsonl": "-", "from": "transcript"}]}}}))
    with gateway(["--config", str(config)], {"PATH": "/usr/bin:/bin",
                                             "HOME": str(Path.home())}) as running:
        assert running.process.wait(timeout=60) == 2
    assert f"routes.speech.input.audio: {tmp_path / 'notes.wav'}: not a WAV file" \
        in running.stderr
    assert "Traceback" not in running.stderr
    with pytest.raises(ConfigError, match=r"/nowhere/questions.wav: cannot read \(No such"):
        AudioSource("mic", InputConfig(audio="/nowhere/questions.wav"), lambda load: None,
                    lambda route: None)


def test_without_the_asr_extra_the_error_names_it(questions: Path, tmp_path: Path) -> None:
    """faster-whisper ships the VAD's ONNX file; here it cannot be imported."""
    shadow = tmp_path / "shadow" / "faster_whisper"
    shadow.mkdir(parents=True)
    (shadow / "__init__.py").write_text(
        "raise ModuleNotFoundError(\"No module named 'faster_whisper'\", "
        "name='faster_whisper')\n")
    script = ("from oricf.gateway.config import InputConfig\n"
              "from oricf.gateway.sources.audio_source import AudioSource\n"
              f"AudioSource('mic', InputConfig(audio={str(questions)!r}), print, print)\n")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                            env={"PYTHONPATH": str(shadow.parent), "PATH": "/usr/bin:/bin"},
                            check=False)
    assert "ConfigError: routes.mic.input.audio: cutting audio into utterances needs the " \
           "Silero VAD that faster-whisper ships: pip install 'oricf[asr]'" in result.stderr


def test_gateway_modules_import_audio_libraries_only_for_audio_routes() -> None:
    check = ("import sys\n"
             "import oricf.gateway.shells.without_ros, oricf.gateway.sources\n"
             "assert 'oricf.services.asr' not in sys.modules\n"
             "import oricf.gateway.sources.audio_source\n"
             "heavy = {'sounddevice', 'faster_whisper', 'rclpy'} & set(sys.modules)\n"
             "assert not heavy, heavy\n")
    result = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True,
                            check=False)
    assert result.returncode == 0, result.stderr


def test_vad_settings_belong_to_audio_inputs_and_wav_paths_to_the_yaml(tmp_path: Path) -> None:
    route = {"call": {"service": "asr", "method": "Transcribe"},
             "outputs": [{"jsonl": "-", "from": "transcript"}]}
    config = tmp_path / "p.yaml"
    config.write_text(yaml.safe_dump({
        "endpoints": {"asr": {"address": "127.0.0.1:50052"}},
        "routes": {"wav": {**route, "input": {"audio": "q.wav", "vad": {"threshold": 0.6}}},
                   "mic": {**route, "input": {"audio": "default"}}}}))
    routes = load_pipeline(config).routes
    assert routes["wav"].input.audio == str(tmp_path / "q.wav")
    assert routes["wav"].input.vad is not None and routes["wav"].input.vad.threshold == 0.6
    assert routes["mic"].input.audio == "default"
    config.write_text(yaml.safe_dump({
        "endpoints": {"asr": {"address": "127.0.0.1:50052"}},
        "routes": {"typed": {**route, "input": {"text": "-", "vad": {}}}}}))
    with pytest.raises(ConfigError, match=r"routes.typed.input: .*vad: only with audio"):
        load_pipeline(config)
