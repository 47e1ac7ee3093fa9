"""oricf.audio: WAV parsing, sample conversion, mix-down, resampling and speech synthesis."""

import struct
import subprocess
import tracemalloc

import numpy as np
import pytest

from oricf.audio import (
    MODEL_RATE,
    ModelInput,
    PcmAudio,
    Resampler,
    decode_audio,
    encode_wav,
    mix_down,
    parse_wav,
    pcm_from_bytes,
    resample,
    synthesize,
    to_float32,
    to_int16,
    to_model_input,
)
from oricf.errors import InvalidInput


def tone(frequency: float, rate: int, seconds: float = 1.0, amplitude: float = 0.5) -> np.ndarray:
    t = np.arange(int(rate * seconds)) / rate
    return (amplitude * np.sin(2 * np.pi * frequency * t)).astype(np.float32)


def peak_frequency(samples: np.ndarray, rate: int) -> float:
    spectrum = np.abs(np.fft.rfft(samples * np.hanning(len(samples))))
    return float(np.fft.rfftfreq(len(samples), 1 / rate)[spectrum.argmax()])


def rms(samples: np.ndarray) -> float:
    return float(np.sqrt(np.mean(samples.astype(np.float64) ** 2)))


def wav_with_format(tag: int, bits: int, rate: int = 16000, channels: int = 1,
                    body: bytes = b"\0\0" * 10) -> bytes:
    fmt = struct.pack("<HHIIHH", tag, channels, rate, rate * channels * bits // 8,
                      channels * bits // 8, bits)
    chunks = b"fmt " + struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack("<I", len(body))
    return b"RIFF" + struct.pack("<I", 4 + len(chunks) + len(body)) + b"WAVE" + chunks + body


# Converting 24 MB of samples at 384 kHz holds one block of MIX_FRAMES frames as float32
# (8 MB for 32 channels) and the resampler's taps for it (about 27 MB).
MAX_CONVERSION_MB = 45


# --- WAV ------------------------------------------------------------------------------------

@pytest.mark.parametrize("channels", [1, 2])
def test_wav_round_trip(channels: int) -> None:
    frames = np.arange(-300, 300, dtype=np.int16).reshape(-1, channels) * 50
    audio = parse_wav(encode_wav(frames, 22050))
    assert audio.sample_rate == 22050 and audio.channels == channels
    np.testing.assert_array_equal(audio.samples, frames)
    assert audio.duration_s == pytest.approx(len(frames) / 22050)


def test_wav_with_extra_chunks_and_odd_padding() -> None:
    wav = encode_wav(np.array([1, 2, 3], dtype=np.int16), 16000)
    # A LIST chunk of odd length (padded to even) between the header and fmt.
    extra = b"LIST" + struct.pack("<I", 3) + b"abc\0"
    wav = wav[:12] + extra + wav[12:]
    np.testing.assert_array_equal(parse_wav(wav).samples[:, 0], [1, 2, 3])


def test_extensible_pcm_wav_is_accepted() -> None:
    fmt = struct.pack("<HHIIHHHHIH14s", 0xFFFE, 1, 16000, 32000, 2, 16, 22, 16, 4, 1,
                      b"\x00\x00\x00\x00\x10\x00\x80\x00\x00\xaa\x00\x38\x9b\x71")
    body = np.array([5, -5], dtype="<i2").tobytes()
    chunks = b"fmt " + struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack("<I", 4) + body
    wav = b"RIFF" + struct.pack("<I", 4 + len(chunks)) + b"WAVE" + chunks
    np.testing.assert_array_equal(parse_wav(wav).samples[:, 0], [5, -5])


def test_wav_written_to_a_pipe_is_read_to_its_end() -> None:
    # espeak-ng --stdout cannot seek back to fill in the sizes: it writes placeholders.
    wav = subprocess.run(["espeak-ng", "--stdout", "hello robot"], check=True,
                         capture_output=True).stdout
    assert struct.unpack_from("<I", wav, 40)[0] >= 0x7FFF0000
    audio = parse_wav(wav)
    assert audio.sample_rate == 22050 and audio.channels == 1
    assert audio.frames == (len(wav) - 44) // 2 and 0.4 < audio.duration_s < 2.0
    # The same with the 0xFFFFFFFF placeholder and a final half frame.
    other = wav[:40] + struct.pack("<I", 0xFFFFFFFF) + wav[44:] + b"\x01"
    assert parse_wav(other).frames == audio.frames


@pytest.mark.parametrize(("data", "message"), [
    (b"", "not a WAV file"),
    (b"hello, this is not audio at all", "not a WAV file"),
    (b"\x89PNG\r\n\x1a\n" + bytes(100), "not a WAV file"),
    (encode_wav(np.zeros(1000, np.int16), 16000)[:500], "truncated WAV file"),
    (encode_wav(np.zeros(10, np.int16), 16000)[:36], "no 'data' chunk"),
    (b"RIFF\x04\x00\x00\x00WAVE", "no valid 'fmt ' chunk"),
    (wav_with_format(1, 8), "only 16-bit PCM"),
    (wav_with_format(3, 32, body=bytes(40)), "only 16-bit PCM"),
    (wav_with_format(1, 16, rate=0), "sample_rate must be > 0"),
    (wav_with_format(1, 16, channels=0), "channels must be"),
    (wav_with_format(1, 16, body=b"\0\0\0"), "not a whole number of frames"),
])
def test_bad_wav_is_refused_clearly(data: bytes, message: str) -> None:
    with pytest.raises(InvalidInput, match=message):
        parse_wav(data)


# --- pcm_s16le and decode_audio -------------------------------------------------------------

def test_pcm_interleaved_frames() -> None:
    data = np.array([1, -1, 2, -2, 3, -3], dtype="<i2").tobytes()
    audio = pcm_from_bytes(data, 8000, 2)
    np.testing.assert_array_equal(audio.samples, [[1, -1], [2, -2], [3, -3]])
    assert audio.frames == 3 and audio.duration_s == pytest.approx(3 / 8000)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"data": b"\0\0\0", "sample_rate": 16000}, "not a whole number of frames"),
    ({"data": b"\0\0\0\0\0\0", "sample_rate": 16000, "channels": 2}, "not a whole number"),
    ({"data": b"\0\0", "sample_rate": 0}, "sample_rate must be > 0"),
    ({"data": b"\0\0", "sample_rate": 10_000_000}, "above the"),
    ({"data": b"\0\0", "sample_rate": 16000, "channels": 99}, "channels must be"),
])
def test_bad_pcm_is_refused_clearly(kwargs: dict, message: str) -> None:
    with pytest.raises(InvalidInput, match=message):
        pcm_from_bytes(**kwargs)


@pytest.mark.parametrize(("encoding", "data", "message"), [
    ("mp3", b"\0\0", "unknown audio encoding 'mp3'"),
    ("", b"\0\0", "audio encoding is missing"),
    ("pcm_s16le", b"", "audio data is empty"),
    ("wav", b"", "audio data is empty"),
    ("wav", encode_wav(np.zeros(0, np.int16), 16000), "holds no samples"),
])
def test_decode_audio_refuses(encoding: str, data: bytes, message: str) -> None:
    with pytest.raises(InvalidInput, match=message):
        decode_audio(data, encoding, 16000)


def test_decode_audio_enforces_the_length_limit() -> None:
    data = np.zeros(16000 * 3, np.int16).tobytes()
    assert decode_audio(data, "PCM_S16LE", 16000, 0, max_seconds=3).duration_s == 3
    with pytest.raises(InvalidInput, match=r"audio of 3.0 s is over the limit of 2 s"):
        decode_audio(data, "pcm_s16le", 16000, 0, max_seconds=2)


# --- conversion -----------------------------------------------------------------------------

def test_int16_float32_round_trip_and_clipping() -> None:
    samples = np.array([-32768, -1, 0, 1, 32767], dtype=np.int16)
    floats = to_float32(samples)
    assert floats.dtype == np.float32 and floats.min() == -1.0 and floats.max() < 1.0
    np.testing.assert_array_equal(to_int16(floats), samples)
    np.testing.assert_array_equal(to_int16(np.array([-2.0, 2.0])), [-32768, 32767])


def test_mix_down_averages_channels() -> None:
    frames = np.array([[1.0, 3.0], [-1.0, 1.0]], dtype=np.float32)
    np.testing.assert_allclose(mix_down(frames), [2.0, 0.0])
    np.testing.assert_allclose(mix_down(frames[:, :1]), [1.0, -1.0])


# --- resampling -----------------------------------------------------------------------------

@pytest.mark.parametrize("source", [8000, 11025, 22050, 44100, 48000, 44056])
def test_resampling_keeps_pitch_length_and_level(source: int) -> None:
    out = resample(tone(440, source), source, MODEL_RATE)
    assert len(out) == MODEL_RATE
    assert peak_frequency(out, MODEL_RATE) == pytest.approx(440, abs=2)
    reference = tone(440, MODEL_RATE)
    # Away from the edges the band-limited result matches the ideal tone closely.
    assert np.abs(out[400:-400] - reference[400:-400]).max() < 0.01


def test_resampling_removes_what_the_target_rate_cannot_carry() -> None:
    # 12 kHz is above the 8 kHz Nyquist limit of 16 kHz audio: it must not fold back.
    assert rms(resample(tone(12000, 48000), 48000, MODEL_RATE)[500:-500]) < 0.001
    assert rms(resample(tone(3000, 48000), 48000, MODEL_RATE)[500:-500]) > 0.3


def test_chunked_resampling_equals_one_shot() -> None:
    rng = np.random.default_rng(7)
    signal = rng.standard_normal(44100).astype(np.float32) * 0.1
    resampler = Resampler(44100, MODEL_RATE)
    parts, start = [], 0
    while start < len(signal):
        size = int(rng.integers(1, 2000))
        parts.append(resampler.push(signal[start:start + size]))
        start += size
    parts.append(resampler.flush())
    np.testing.assert_allclose(np.concatenate(parts), resample(signal, 44100, MODEL_RATE),
                               atol=1e-6)


def test_to_model_input_mixes_and_resamples() -> None:
    left = to_int16(tone(500, 48000, 0.5))
    frames = np.stack([left, left], axis=1)
    out = to_model_input(pcm_from_bytes(frames.tobytes(), 48000, 2))
    assert out.dtype == np.float32 and len(out) == MODEL_RATE // 2
    assert peak_frequency(out, MODEL_RATE) == pytest.approx(500, abs=4)


def test_model_input_holds_one_block_of_many_channels_not_the_whole_audio() -> None:
    """24 MB of samples at 384 kHz in 32 channels: converted whole, they were held as
    float32 twice over (96 MB); in blocks, the conversion holds one block of them (8 MB)
    beside the resampler's own block of taps."""
    rng = np.random.default_rng(3)
    frames = rng.integers(-3000, 3000, (24 * 1024 * 1024 // 64, 32), dtype=np.int16)
    expected = resample(to_float32(frames).mean(axis=1), 384_000, MODEL_RATE)
    tracemalloc.start()
    try:
        out = to_model_input(PcmAudio(frames, 384_000))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak / 2**20 < MAX_CONVERSION_MB, f"held {peak / 2**20:.0f} MiB"
    np.testing.assert_allclose(out, expected, atol=1e-6)


def test_model_input_pushed_in_pieces_equals_one_shot() -> None:
    rng = np.random.default_rng(5)
    frames = rng.integers(-3000, 3000, (100_000, 3), dtype=np.int16)
    converter = ModelInput(44100, 3)
    start = 0
    while start < len(frames):
        size = int(rng.integers(1, 9000))
        converter.push(frames[start:start + size])
        start += size
    assert converter.frames == len(frames)
    np.testing.assert_allclose(converter.finish(),
                               to_model_input(PcmAudio(frames, 44100)), atol=1e-6)


# --- synthesis ------------------------------------------------------------------------------

def test_synthesize_makes_real_speech() -> None:
    speech = synthesize("How many people do you see")
    assert speech.dtype == np.int16
    assert 1.0 < len(speech) / MODEL_RATE < 4.0
    assert rms(speech) > 500   # clearly not silence
    slower = synthesize("How many people do you see", voice="en-gb", rate=120)
    assert len(slower) > len(speech)


def test_synthesize_at_another_rate() -> None:
    speech = synthesize("hello robot", sample_rate=44100)
    assert 0.4 < len(speech) / 44100 < 2.0
