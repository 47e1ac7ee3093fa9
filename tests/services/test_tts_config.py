"""configs/services/tts.yaml: a voice is a declaration, checked at start; mistakes name the
file and key, and a voice that cannot speak stops the service before it serves."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from oricf.errors import ConfigError, ModelMissing
from oricf.services.tts.espeak import EspeakVoice
from oricf.services.tts.service import create_model
from oricf.store import ModelStore
from tests.support.services import service_config


def test_the_shipped_config_declares_both_engines() -> None:
    config = service_config("tts")
    assert config.default_voice == "joe"
    assert {name: v.engine for name, v in config.voices.items()} == {
        "joe": "piper", "espeak": "espeak-ng"}
    assert config.server.listen == "127.0.0.1:0"  # loopback (the test's free port)


@pytest.mark.parametrize(("overrides", "said"), [
    ({"voices": {"joe": {"voice": "en-us"}}}, "voices.joe.piper.voice: unknown key"),
    ({"voices": {"x": {"engine": "festival"}}}, "voices.x.engine"),
    ({"voices": {"x": {"engine": "espeak-ng", "voice": "--rm -rf"}}}, "voices.x.espeak-ng.voice"),
    ({"voices": {"x": {"engine": "espeak-ng", "words_per_minute": 1000}}},
     "voices.x.espeak-ng.words_per_minute"),
    ({"voices": {"x": {"engine": "espeak-ng", "word_gap_ms": 15}}},
     "voices.x.espeak-ng.word_gap_ms"),
    ({"default_voice": "nobody"}, "default_voice: 'nobody' is not one of the voices"),
    ({"voices": {"bad name!": {"engine": "espeak-ng"}}}, "is not a voice name"),
    ({"text": {"max_chars": 0}}, "text.max_chars"),
    ({"audio": {"sentence_pause_ms": -1}}, "audio.sentence_pause_ms"),
    ({"audio": {"max_audio_s": 0}}, "audio.max_audio_s"),
    ({"text": {"max_chars": 5000}}, "max_spoken_chars (4000) must be at least max_chars (5000)"),
    ({"voices": {"joe": {"max_run_phonemes": 4}}}, "voices.joe.piper.max_run_phonemes"),
])
def test_mistakes_name_the_file_and_key(overrides: dict[str, Any], said: str) -> None:
    with pytest.raises(ConfigError) as refused:
        service_config("tts", overrides)
    assert "tts.yaml" in str(refused.value) and said in str(refused.value)


def test_a_voice_espeak_ng_lacks_stops_the_start() -> None:
    config = service_config("tts", {"voices": {"espeak": {"voice": "xx-nonexistent"}}})
    model = create_model(config, ModelStore())
    with pytest.raises(ConfigError) as refused:
        model.load()
    assert "voices.espeak: espeak-ng cannot speak with voice 'xx-nonexistent'" in str(
        refused.value)


def test_a_missing_voice_model_names_the_pull_command(tmp_path: Path) -> None:
    with pytest.raises(ModelMissing) as refused:
        create_model(service_config("tts"), ModelStore(root=tmp_path))
    assert "oricf models pull piper-joe-medium" in str(refused.value)


def test_espeak_ng_complaining_about_its_home_still_speaks(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """As in a container whose user cannot write its home: espeak-ng's audio library says so
    on stderr, and the WAV it writes is whole all the same."""
    monkeypatch.setenv("XDG_CONFIG_HOME", "/etc/passwd/not-a-folder")
    monkeypatch.setenv("HOME", "/etc/passwd/not-a-folder")
    voice = EspeakVoice("espeak", service_config("tts").voices["espeak"])
    voice.load()
    assert len(voice.speak("Still speaking.", 1.0)) / voice.sample_rate > 0.5
