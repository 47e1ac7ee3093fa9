"""Hostile MCAP files read by the replay's reader: chunks that expand to far more than the
file (claiming it or lying about it), a million tiny records in a few kilobytes. Each is
refused with a RecordingError naming the file and the chunk's byte, in bounded memory."""

from __future__ import annotations

import json
import subprocess
import sys
import zlib
from pathlib import Path

import lz4.frame
import pytest
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.records import Chunk, DataEnd, Footer, Header

from oricf.gateway.recording.chunks import MAX_CHUNK_BYTES, MAX_CHUNK_RECORDS, MIN_TOTAL_BYTES
from oricf.gateway.recording.mcap_reader import MAGIC, McapFile
from oricf.gateway.recording.recorder import RecordingError

GIB = 1 << 30
CHUNK_AT = len(MAGIC) + 9 + 4 + 4  # after the magic and a header record of empty strings


def mcap_with_chunk(path: Path, content: bytes, compression: str, claimed: int | None = None,
                    crc: int = 0) -> None:
    """An MCAP file of one chunk holding `content`, compressed, claiming `claimed` bytes."""
    data = {"zstd": zstandard.ZstdCompressor(level=19).compress,
            "lz4": lz4.frame.compress, "": bytes}[compression](content)
    write_mcap(path, Chunk(message_start_time=0, message_end_time=0,
                           uncompressed_size=len(content) if claimed is None else claimed,
                           uncompressed_crc=crc, compression=compression, data=data))


def write_mcap(path: Path, *chunks: Chunk) -> None:
    builder = RecordBuilder()
    Header(profile="", library="").write(builder)
    for chunk in chunks:
        chunk.write(builder)
    DataEnd(data_section_crc=0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    path.write_bytes(MAGIC + bytes(builder.end()) + MAGIC)


def zeros_stream(size: int, prefix: bytes = b"") -> bytes:
    """`prefix` and zero bytes up to `size`, compressed by zstd without holding them in
    memory."""
    out = zstandard.ZstdCompressor(level=3).compressobj(size=size)
    parts, left = [out.compress(prefix)], size - len(prefix)
    while left:
        parts.append(out.compress(bytes(min(left, 1 << 20))))
        left -= min(left, 1 << 20)
    return b"".join(parts) + out.flush()


def tiny_records(count: int) -> bytes:
    """`count` records of a type a chunk may hold but a replay skips, 9 bytes each."""
    return (bytes([0x7F]) + (0).to_bytes(8, "little")) * count


def read_all(path: Path) -> int:
    file = McapFile(path)
    try:
        return sum(1 for _ in file.records())
    finally:
        file.close()


def test_a_chunk_claiming_a_gibibyte_is_refused_before_decompressing(tmp_path: Path) -> None:
    path = tmp_path / "bomb.mcap"
    write_mcap(path, Chunk(message_start_time=0, message_end_time=0, uncompressed_size=GIB,
                           uncompressed_crc=0, compression="zstd", data=zeros_stream(GIB)))
    assert path.stat().st_size < 64_000
    with pytest.raises(RecordingError) as err:
        read_all(path)
    assert str(err.value) == (f"{path}: the chunk at byte {CHUNK_AT:,} claims {GIB:,} bytes "
                              f"uncompressed, more than {MAX_CHUNK_BYTES:,}")


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_a_chunk_that_holds_more_than_it_claims_is_refused(compression: str,
                                                           tmp_path: Path) -> None:
    path = tmp_path / "liar.mcap"
    mcap_with_chunk(path, bytes(32 << 20), compression, claimed=1000)
    with pytest.raises(RecordingError, match=f"the chunk at byte {CHUNK_AT:,} holds more "
                                             f"than the 1,000 bytes it claims"):
        read_all(path)


def test_a_chunk_of_a_million_tiny_records_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "tiny.mcap"
    mcap_with_chunk(path, tiny_records(1_000_000), "zstd")
    assert path.stat().st_size < 10_000
    with pytest.raises(RecordingError, match=f"holds more than {MAX_CHUNK_RECORDS:,} records"):
        read_all(path)


def test_a_files_chunks_together_expand_only_so_much(tmp_path: Path) -> None:
    """Each chunk within the cap, all of them beyond what a file this small may hold."""
    size = MAX_CHUNK_BYTES // 2 + 1
    record = bytes([0x7F]) + (size - 9).to_bytes(8, "little")  # one record a replay skips
    chunk = Chunk(message_start_time=0, message_end_time=0, uncompressed_size=size,
                  uncompressed_crc=0, compression="zstd", data=zeros_stream(size, record))
    path = tmp_path / "many.mcap"
    write_mcap(path, chunk, chunk)
    second = CHUNK_AT + 9 + 8 * 3 + 4 + 4 + len("zstd") + 8 + len(chunk.data)
    with pytest.raises(RecordingError) as err:
        read_all(path)
    assert str(err.value).startswith(f"{path}: the chunk at byte {second:,} takes the "
                                     f"file's chunks past {MIN_TOTAL_BYTES:,} bytes")


def test_a_damaged_chunk_is_named(tmp_path: Path) -> None:
    path = tmp_path / "crc.mcap"
    content = tiny_records(10)
    mcap_with_chunk(path, content, "lz4", crc=zlib.crc32(content) ^ 1)
    with pytest.raises(RecordingError, match="its checksum does not match its content"):
        read_all(path)
    mcap_with_chunk(path, content, "zstd", claimed=len(content) + 5)
    with pytest.raises(RecordingError, match=f"holds 90 bytes, not the {95} it claims"):
        read_all(path)


def test_honest_chunks_still_read(tmp_path: Path) -> None:
    for compression in ("zstd", "lz4", ""):
        mcap_with_chunk(tmp_path / "ok.mcap", tiny_records(1000), compression)
        assert read_all(tmp_path / "ok.mcap") == 0  # skipped record types, none refused


def test_a_compression_bomb_costs_little_memory(tmp_path: Path) -> None:
    """In a process of its own, so that its peak memory is its own: VmHWM, the high-water
    mark of its own address space (ru_maxrss would carry the forking test run's)."""
    path = tmp_path / "bomb.mcap"
    write_mcap(path, Chunk(message_start_time=0, message_end_time=0, uncompressed_size=1000,
                           uncompressed_crc=0, compression="zstd", data=zeros_stream(GIB)))
    script = ("import json, sys\n"
              "from pathlib import Path\n"
              "from tests.gateway.recording.test_hostile_recordings import read_all\n"
              "from oricf.gateway.recording.recorder import RecordingError\n"
              "try:\n    read_all(Path(sys.argv[1])); error = ''\n"
              "except RecordingError as exc:\n    error = str(exc)\n"
              "peak = next(int(line.split()[1]) * 1024 for line in\n"
              "            Path('/proc/self/status').read_text().splitlines()\n"
              "            if line.startswith('VmHWM:'))\n"
              "print(json.dumps({'error': error, 'peak': peak}))\n")
    done = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True,
                          text=True, timeout=120, check=True)
    result = json.loads(done.stdout)
    assert "holds more than the 1,000 bytes it claims" in result["error"]
    assert result["peak"] < 400 << 20
