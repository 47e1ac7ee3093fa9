"""Audio shared by the speech service, the gateway, the demo and the benchmarks.

Samples travel as little-endian signed 16-bit PCM (``pcm_s16le``) or as a WAV file; models
want mono float32 at 16 kHz. Reading, checking and converting them is numpy only (no audio
library needed), and every problem with the caller's bytes is an InvalidInput that says what
is wrong. Cutting a stream into utterances by voice activity (Silero VAD) lives in
oricf.audio.vad and oricf.audio.endpointing; their settings schema is exported here.

    pcm          int16 frames: checks, conversion to float32, mix-down
    wav          WAV files read and written; decode_audio for request bytes
    resample     band-limited resampling, one-shot or streaming; ModelInput, any audio
                 as a model's input piece by piece
    synth        speech from espeak-ng for tests, demos and benchmarks
    vad          the Silero VAD session and its per-stream state
    endpointing  utterances from a stream, and VadSettings / EndpointingSettings
"""

from oricf.audio.endpointing import EndpointingSettings, VadSettings
from oricf.audio.pcm import (
    INT16_SCALE,
    MAX_CHANNELS,
    MAX_RATE,
    MIN_RATE,
    MODEL_RATE,
    PcmAudio,
    check_format,
    mix_down,
    pcm_from_bytes,
    to_float32,
    to_int16,
)
from oricf.audio.resample import (
    BLOCK,
    MAX_PHASES,
    MIX_FRAMES,
    ROLLOFF,
    ZERO_CROSSINGS,
    ModelInput,
    Resampler,
    resample,
    to_model_input,
)
from oricf.audio.synth import synthesize
from oricf.audio.wav import (
    ENCODINGS,
    STREAMED_DATA_SIZE,
    WAVE_FORMAT_EXTENSIBLE,
    WAVE_FORMAT_PCM,
    decode_audio,
    encode_wav,
    parse_wav,
    wav_header,
)

__all__ = [
    "BLOCK", "ENCODINGS", "INT16_SCALE", "MAX_CHANNELS", "MAX_PHASES", "MAX_RATE", "MIN_RATE",
    "MIX_FRAMES", "MODEL_RATE", "ROLLOFF", "STREAMED_DATA_SIZE", "WAVE_FORMAT_EXTENSIBLE",
    "WAVE_FORMAT_PCM", "ZERO_CROSSINGS", "EndpointingSettings", "ModelInput", "PcmAudio",
    "Resampler", "VadSettings", "check_format", "decode_audio", "encode_wav", "mix_down",
    "parse_wav", "pcm_from_bytes", "resample", "synthesize", "to_float32", "to_int16",
    "to_model_input", "wav_header",
]
