"""An MCAP file read defensively, for replays: a recording may be cut short (a robot that lost
power: no summary, a last record half written), damaged, or no MCAP file at all.

Opening checks what can be checked at once (the file exists, starts like an MCAP file, has a
readable header record) and reads the summary, the file's index of channels and counts, if
the file has one. Messages are then read in file order, one record at a time (memory stays
bounded by a chunk, whatever the length of the recording), chunk checksums validated;
chunks are decompressed within limits (chunks.py), whatever size they claim. Every
problem becomes a RecordingError naming the file and the byte where reading stopped; the
parser's own exceptions, whatever their type, never escape.
"""

from __future__ import annotations

import io
import logging
import os
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from mcap.exceptions import EndOfFile, InvalidMagic, RecordLengthLimitExceeded
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Header, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.summary import Summary

from oricf.gateway.recording.chunks import ChunkReader
from oricf.gateway.recording.recorder import RecordingError
from oricf.logs import quoted

log = logging.getLogger(__name__)

MAGIC = b"\x89MCAP0\r\n"


class McapFile:
    """One MCAP file opened for reading (raises RecordingError if unusable)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._file = _open(path)
        try:
            self.size = os.fstat(self._file.fileno()).st_size
            self.header = self._header()
            self.summary = self._summary()
        except BaseException:
            self._file.close()
            raise

    def _header(self) -> Header:
        if self.size == 0:
            raise RecordingError(f"{self.path}: the file is empty")
        try:
            header = next(self._reader().records)
        except InvalidMagic:
            raise RecordingError(f"{self.path}: not an MCAP file (it does not start with the "
                                 f"MCAP magic bytes)") from None
        except Exception as exc:  # any parser failure means an unusable file
            raise RecordingError(f"{self.path}: not a readable MCAP file: "
                                 f"{_reason(exc)}") from None
        if not isinstance(header, Header):
            raise RecordingError(f"{self.path}: not an MCAP file (no header record)")
        return header

    def _summary(self) -> Summary | None:
        """The summary section, or None for a file without one (cut short, or written so)."""
        if self.size < 2 * len(MAGIC):
            return None
        self._file.seek(-len(MAGIC), io.SEEK_END)
        if self._file.read(len(MAGIC)) != MAGIC:
            return None  # no footer: the writer never finished the file
        try:
            self._file.seek(0)
            return SeekingReader(self._file, record_size_limit=self.size).get_summary()
        except Exception as exc:  # a damaged summary: read the data instead
            log.warning("%s: its summary cannot be read (%s); reading the messages without it",
                        self.path, _reason(exc))
            return None

    def _reader(self, emit_chunks: bool = False) -> StreamReader:
        self._file.seek(0)
        # A record longer than the file is damage, not a reason to allocate gigabytes.
        # Chunks are unpacked here (chunks.py), within limits, not by the library.
        return StreamReader(self._file, validate_crcs=True, record_size_limit=self.size,
                            emit_chunks=emit_chunks)

    def records(self) -> Iterator[Schema | Channel | Message]:
        """The schema, channel and message records in file order; RecordingError where the
        file stops being readable (what came before has been yielded)."""
        chunks = ChunkReader(self.path, self.size)
        try:
            records = self._reader(emit_chunks=True).records
            while True:
                start = self._file.tell()  # where the next top-level record begins
                record = next(records, None)
                if record is None:
                    return
                if isinstance(record, Chunk):
                    yield from chunks.records(record, start)
                elif isinstance(record, Schema | Channel | Message):
                    yield record
        except RecordingError:
            raise
        except (EndOfFile, RecordLengthLimitExceeded):  # a record longer than what is left
            raise RecordingError(f"{self.path}: ends in the middle of a record (near byte "
                                 f"{self._file.tell():,} of {self.size:,}): the recording was "
                                 f"cut short") from None
        except Exception as exc:  # any parser failure means damage here
            raise RecordingError(f"{self.path}: damaged near byte {self._file.tell():,}: "
                                 f"{_reason(exc)}") from None

    def close(self) -> None:
        self._file.close()


def _open(path: Path) -> BinaryIO:
    try:
        return open(path, "rb")  # McapFile.close closes it
    except FileNotFoundError:
        raise RecordingError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise RecordingError(f"{path}: a folder; give the .mcap file in it") from None
    except OSError as exc:
        raise RecordingError(f"{path}: cannot open it: {exc.strerror}") from None


def _reason(exc: Exception) -> str:
    """A parser's message, which may quote the file's bytes: escaped and clipped."""
    return quoted(exc, 300) if str(exc) else type(exc).__name__
