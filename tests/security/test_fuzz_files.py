"""Property-based fuzzing of the files ORICF reads from others: pipeline overlays (YAML),
token files and MCAP recordings. Whatever the bytes, reading ends quickly with the value or
the project's own error (ConfigError, RecordingError) naming the file; never another
exception, a hang, or memory beyond a chunk's worth. Files that are no file (a FIFO,
/dev/zero) stop each command that reads a token at once, naming the file and the key."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import time
import zlib
from pathlib import Path

import lz4.frame
import pytest
import zstandard
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.data_stream import RecordBuilder
from mcap.records import Chunk, DataEnd, Footer, Header
from mcap.writer import CompressionType
from mcap_ros2.writer import Writer

from oricf.config import config_dir
from oricf.errors import ConfigError
from oricf.gateway.config import load_pipeline
from oricf.gateway.recording.mcap_reader import MAGIC, McapFile
from oricf.gateway.recording.pace import MAX_RATE, MIN_RATE, Pace
from oricf.gateway.recording.recorder import RecordingError
from oricf.tls import VISIBLE_ASCII, TokenSource

EXAMPLES = 150
SECONDS = 10  # for one file, far more than a config or a small recording needs
PEOPLE_QA = config_dir() / "pipelines" / "people_qa.yaml"
FUZZ = settings(max_examples=EXAMPLES, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])

# YAML pieces that reach the loader's limits, mixed with text that is almost an overlay.
YAML_PIECES = st.sampled_from([
    "endpoints:\n", "  detector:\n", "    address: 127.0.0.1:1\n", "    deadline_ms: ", "-1\n",
    "routes: {people: {input: {topic: x}}}\n", "a: &a [x, x, x, x, x, x, x, x]\n",
    "b: &b [*a, *a, *a, *a, *a, *a, *a, *a]\n", "c: [*b, *b, *b, *b, *b, *b, *b, *b]\n",
    "d: *missing\n", "e: &e [*e]\n", "<<: *a\n", "[" * 200, "]" * 200, "{" * 70,
    "n: " + "9" * 5000 + "\n", "t: 2001-02-30\n", "f: !!python/object:os.system x\n",
    "s: \"\\x1b[31m\\n\"\n", "\t", "\x00", "\ufeff", "\udcff", "? [a, b]\n: 1\n", "---\n",
    "...\n", "%YAML 1.1\n", "x: !!binary AAAA====\n",
])
YAML_TEXT = st.lists(st.one_of(YAML_PIECES, st.text(max_size=30)), max_size=25).map("".join)
YAML_BYTES = st.one_of(
    YAML_TEXT.map(lambda text: text.encode("utf-8", "surrogatepass")),
    YAML_TEXT.map(lambda text: text.encode("utf-16", "surrogatepass")),
    st.binary(max_size=400))


@FUZZ
@given(data=YAML_BYTES)
def test_any_overlay_gives_a_pipeline_or_a_config_error(data: bytes, tmp_path: Path) -> None:
    overlay = tmp_path / "overlay.yaml"
    overlay.write_bytes(data)
    started = time.monotonic()
    try:
        load_pipeline(PEOPLE_QA, [overlay])
    except ConfigError as exc:
        assert str(overlay) in str(exc) or "people_qa.yaml" in str(exc)
    assert time.monotonic() - started < SECONDS


@FUZZ
@given(data=st.one_of(st.binary(max_size=200), st.text(max_size=60).map(
    lambda text: text.encode("utf-8", "surrogatepass"))))
def test_any_token_file_gives_ascii_tokens_or_a_config_error(data: bytes,
                                                             tmp_path: Path) -> None:
    path = tmp_path / "tokens"
    path.write_bytes(data)
    path.chmod(0o600)
    try:
        tokens = TokenSource(file=path).tokens()
    except ConfigError as exc:
        assert str(exc).startswith(f"{path}: ") and "\n" not in str(exc)
        return
    assert tokens and all(t and all(ord(c) in VISIBLE_ASCII for c in t) for t in tokens)


def hostile_token_command(case: str, folder: Path) -> tuple[list[str], str]:
    """`oricf` arguments that read one hostile token file, and what the error must say."""
    fifo, unusable = folder / "approvers.fifo", folder / "tokens"
    os.mkfifo(fifo, 0o600)
    unusable.write_bytes("t\u00f6ken\u20ac\n".encode() if case == "mcp" else b"\n")
    unusable.chmod(0o600)
    if case == "gateway":  # a FIFO once held the gateway at start, for ever
        return (["gateway", "--config", str(PEOPLE_QA), "--set",
                 f"control.listen=unix:{folder / 'control.sock'}", "--set",
                 f"control.approvers.file={fifo}", "--check"],
                f"control.approvers.file: {fifo}: a FIFO (named pipe), not a token file")
    if case == "mcp":  # once a UnicodeEncodeError traceback
        return (["mcp", "--attach", f"unix:{folder / 'none.sock'}", "--token-file",
                 str(unusable)], f"--token-file: {unusable}: line 1, character 2")
    if case == "mcp-tls":  # uvicorn would open the certificate by name and wait on it
        key = folder / "key.pem"
        key.write_bytes(b"not a key")
        key.chmod(0o600)
        return (["mcp", "--config", str(PEOPLE_QA), "--transport", "http", "--tls-cert",
                 str(fifo), "--tls-key", str(key)],
                f"--tls-cert/--tls-key: tls.cert: {fifo}: a FIFO (named pipe)")
    return (["serve", "detector", "--auth-token-file", str(unusable)],
            f"detector.yaml: server.auth.file: {unusable}: no token")


@pytest.mark.parametrize("case", ["gateway", "mcp", "mcp-tls", "serve"])
def test_a_hostile_token_file_stops_the_command_at_once_naming_it(case: str,
                                                                  tmp_path: Path) -> None:
    args, reason = hostile_token_command(case, tmp_path)
    done = subprocess.run([sys.executable, "-m", "oricf", *args], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2, done.stderr
    assert reason in done.stderr and "Traceback" not in done.stderr


def chunk_bytes(content: bytes, compression: str) -> bytes:
    return {"zstd": zstandard.ZstdCompressor().compress, "lz4": lz4.frame.compress,
            "": bytes}[compression](content)


@st.composite
def hostile_chunk(draw: st.DrawFn) -> bytes:
    """An MCAP file of one chunk: content of records or noise, compressed any way, claiming
    any size and checksum."""
    content = draw(st.one_of(
        st.binary(max_size=300),
        st.integers(1, 200_000).map(lambda n: (b"\x7f" + bytes(8)) * n),
        st.integers(1, 8 << 20).map(bytes)))
    compression = draw(st.sampled_from(["zstd", "lz4", "", "bz2"]))
    claimed = draw(st.one_of(st.just(len(content)), st.integers(0, 2**64 - 1)))
    crc = draw(st.sampled_from([0, zlib.crc32(content), 1]))
    builder = RecordBuilder()
    Header(profile="ros2", library="fuzz").write(builder)
    Chunk(message_start_time=0, message_end_time=0, uncompressed_size=claimed,
          uncompressed_crc=crc, compression=compression,
          data=chunk_bytes(content, compression if compression != "bz2" else "")
          ).write(builder)
    DataEnd(data_section_crc=0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    return MAGIC + bytes(builder.end()) + MAGIC


def recording(compression: str) -> bytes:
    """A small valid rosbag2-style recording: text messages at odd times."""
    out = io.BytesIO()
    writer = Writer(out, compression=CompressionType[compression.upper()])
    text = writer.register_msgdef("std_msgs/msg/String", "string data\n")
    for i, at in enumerate([0, 1, 2**63, 5, 2**64 - 1]):
        writer.write_message("/question", text, {"data": f"q{i}"}, log_time=at,
                             publish_time=at)
    writer.finish()
    return out.getvalue()


@st.composite
def damaged_recording(draw: st.DrawFn) -> bytes:
    """A valid recording with bytes flipped, cut short, or both."""
    data = bytearray(recording(draw(st.sampled_from(["zstd", "lz4"]))))
    for _ in range(draw(st.integers(0, 8))):
        data[draw(st.integers(0, len(data) - 1))] = draw(st.integers(0, 255))
    return bytes(data[:draw(st.integers(0, len(data)))])


def read_all(path: Path) -> None:
    file = McapFile(path)
    try:
        for _ in file.records():
            pass
    finally:
        file.close()


@FUZZ
@given(data=st.one_of(hostile_chunk(), damaged_recording(), st.binary(max_size=300).map(
    lambda noise: MAGIC + noise)))
def test_any_recording_is_read_or_refused_with_a_recording_error(data: bytes,
                                                                 tmp_path: Path) -> None:
    path = tmp_path / "fuzz.mcap"
    path.write_bytes(data)
    started = time.monotonic()
    try:
        read_all(path)
    except RecordingError as exc:
        assert str(exc).startswith(f"{path}: ")
        assert "\n" not in str(exc) and "\x1b" not in str(exc)
    assert time.monotonic() - started < SECONDS


@FUZZ
@given(times=st.lists(st.integers(0, 2**64 - 1), max_size=20),
       rate=st.one_of(st.floats(MIN_RATE, MAX_RATE), st.just(0.0)))
def test_any_times_give_a_finite_wait(times: list[int], rate: float, tmp_path: Path) -> None:
    pace = Pace(tmp_path / "x.mcap", rate)
    now = 0.0
    for at in times:
        wait = pace.wait_s(at, now)
        assert 0 <= wait <= 1e9  # finite, and never what a thread's wait refuses
        now += min(wait, 1.0)
