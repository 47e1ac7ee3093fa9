"""The speech service's config: the shipped file, and bad keys named with their path."""

import pytest

from oricf.errors import ConfigError
from tests.support.services import service_config


def test_the_shipped_config_is_valid() -> None:
    config = service_config("asr")
    assert config.model.backend == "faster-whisper"
    assert config.model.options.beam_size == 5 and config.model.options.compute_type == "int8"
    assert config.endpointing.min_silence_ms == 400


@pytest.mark.parametrize(("overrides", "message"), [
    ({"model": {"backend": "vosk"}}, "model.backend: unknown back end 'vosk' (known: "
                                     "faster-whisper)"),
    ({"model": {"options": {"beam_sise": 2}}}, "model.options: faster-whisper options: "
                                               "beam_sise: Extra inputs are not permitted"),
    ({"model": {"options": {"beam_size": 0}}}, "beam_size: Input should be greater than"),
    ({"model": {"threads": 0}}, "model.threads: Input should be greater than or equal to 1"),
    ({"endpointing": {"threshold": 1.5}}, "endpointing.threshold"),
    ({"endpointing": {"max_utterance_s": 40}}, "max_utterance_s must not exceed"),
    ({"audio": {"max_seconds": 3}}, "audio.max_seconds: unknown key"),
    ({"audio": {"max_decoded_mb": 0}}, "audio.max_decoded_mb: Input should be greater than 0"),
])
def test_bad_config_names_the_key(overrides: dict, message: str) -> None:
    with pytest.raises(ConfigError) as error:
        service_config("asr", overrides)
    assert "asr.yaml" in str(error.value)
    assert message in str(error.value)
