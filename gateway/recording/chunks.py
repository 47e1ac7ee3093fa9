"""The records inside an MCAP chunk, decompressed within limits.

A chunk says how large it is uncompressed, and the mcap library believes it: a few
kilobytes of zstd that claim (or hold) a gigabyte are decompressed whole into memory, and
all the records of a chunk are parsed into one list before the first is used. Here a
chunk's claim is checked against a cap before anything is decompressed, decompression
stops one byte past the claim (a chunk that holds more than it says is damaged), a file's
chunks together may expand only so much, and the records are parsed one at a time, up to
a count per chunk.
"""

from __future__ import annotations

import io
import zlib
from collections.abc import Iterator
from pathlib import Path

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Schema

from oricf.gateway.recording.recorder import RecordingError
from oricf.logs import quoted

MAX_CHUNK_BYTES = 64 << 20  # uncompressed; rosbag2 and --record write chunks under 1 MiB
MAX_CHUNK_RECORDS = 100_000  # records in one chunk
MAX_EXPANSION = 1000  # a file's chunks expand to at most this many times its size ...
MIN_TOTAL_BYTES = MAX_CHUNK_BYTES  # ... or this much, for a small file
READ_STEP = 1 << 20  # bytes decompressed at a time


class ChunkReader:
    """Unpacks the chunks of one file, counting what they expand to."""

    def __init__(self, path: Path, file_size: int) -> None:
        self.path = path
        self.budget = max(MAX_EXPANSION * file_size, MIN_TOTAL_BYTES)
        self.expanded = 0

    def records(self, chunk: Chunk, offset: int) -> Iterator[Schema | Channel | Message]:
        """The schema, channel and message records of the chunk at byte `offset`."""
        data = self._data(chunk, offset)
        stream = ReadDataStream(io.BytesIO(data))
        count = 0
        while stream.count < len(data):
            count += 1
            if count > MAX_CHUNK_RECORDS:
                raise self._error(offset, f"holds more than {MAX_CHUNK_RECORDS:,} records")
            opcode, length = stream.read1(), stream.read8()
            if length > len(data) - stream.count:
                raise self._error(offset, "a record longer than the chunk")
            if opcode == Opcode.CHANNEL:
                yield Channel.read(stream)
            elif opcode == Opcode.MESSAGE:
                yield Message.read(stream, length)
            elif opcode == Opcode.SCHEMA:
                yield Schema.read(stream)
            else:  # a record type a chunk may hold but a replay does not use
                stream.read(length)

    def _data(self, chunk: Chunk, offset: int) -> bytes:
        claimed = chunk.uncompressed_size
        if claimed > MAX_CHUNK_BYTES:
            raise self._error(offset, f"claims {claimed:,} bytes uncompressed, more than "
                                      f"{MAX_CHUNK_BYTES:,}")
        if self.expanded + claimed > self.budget:
            raise self._error(offset, f"takes the file's chunks past {self.budget:,} bytes "
                                      f"uncompressed ({MAX_EXPANSION} times the file's size, "
                                      f"at least {MIN_TOTAL_BYTES:,})")
        data = self._decompress(chunk, claimed, offset)
        if len(data) > claimed:
            raise self._error(offset, f"holds more than the {claimed:,} bytes it claims")
        if len(data) < claimed:
            raise self._error(offset, f"holds {len(data):,} bytes, not the {claimed:,} it "
                                      f"claims")
        self.expanded += claimed
        if chunk.uncompressed_crc != 0 and zlib.crc32(data) != chunk.uncompressed_crc:
            raise self._error(offset, "its checksum does not match its content")
        return data

    def _decompress(self, chunk: Chunk, claimed: int, offset: int) -> bytes:
        """At most one byte more than claimed, so a chunk that lies is caught at once."""
        limit = claimed + 1
        try:
            if chunk.compression == "zstd":
                return _zstd_at_most(chunk.data, limit)
            if chunk.compression == "lz4":
                return _lz4_at_most(chunk.data, limit)
        except (zstandard.ZstdError, RuntimeError, ValueError) as exc:
            raise self._error(offset, f"cannot be decompressed: {quoted(exc)}") from None
        if chunk.compression == "":
            return chunk.data
        raise self._error(offset, f"compressed with {quoted(chunk.compression, 40)}, which "
                                  f"a replay cannot read")

    def _error(self, offset: int, problem: str) -> RecordingError:
        return RecordingError(f"{self.path}: the chunk at byte {offset:,} {problem}")


def _zstd_at_most(data: bytes, limit: int) -> bytes:
    reader = zstandard.ZstdDecompressor().stream_reader(io.BytesIO(data))
    out = bytearray()
    while len(out) < limit and (piece := reader.read(min(READ_STEP, limit - len(out)))):
        out += piece
    return bytes(out)


def _lz4_at_most(data: bytes, limit: int) -> bytes:
    decompressor = lz4.frame.LZ4FrameDecompressor()
    out = bytearray()
    while len(out) < limit and not decompressor.eof:
        piece = decompressor.decompress(data, max_length=min(READ_STEP, limit - len(out)))
        data = b""  # the decompressor keeps the input it has not used yet
        if not piece:
            break
        out += piece
    return bytes(out)
