# Copyright 2026 The cone_feeder_sim Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
Reading run logs back, also when they are truncated or damaged, without rclpy.

:func:`open_recording` reads what a replay needs to know up front (topics, types, QoS,
metadata, time range). A complete file is read through its index (messages in log-time
order, seeking to an offset). A file without summary and footer (the process was killed,
the disk filled up, the copy was cut short) is read sequentially up to the first record
that is incomplete or fails its CRC: :attr:`Recording.problem` says why, and everything
before that point is still delivered. :class:`RecordStream` is that sequential reading on
its own (the records of a stream in file order, up to the first unreadable one), for
readers that want the records themselves. A run split by the recorder into several files
is read as one (:func:`run_parts`, :class:`SplitRecording`); :func:`recover_mcap` copies
the readable part of a damaged file into a complete one.
"""

from collections.abc import Iterator, Sequence
import dataclasses
from dataclasses import dataclass, field
import os
from pathlib import Path
import struct
from typing import Any, BinaryIO

from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import (
    Attachment, Channel, Footer, Header, McapRecord, Message, Metadata, Schema)
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from .mcap_writer import _open_for_writing, LIBRARY
from .run_recorder import PART_METADATA_NAME, part_number, part_path
from ..errors import RecordingError

try:  # zstandard is optional for mcap; only needed to recognise its errors here.
    import zstandard
except ImportError:  # pragma: no cover - zstandard is installed with mcap's zstd support
    zstandard = None

__all__ = [
    'RecordedMessage',
    'RecordedTopic',
    'Recording',
    'RecordStream',
    'open_recording',
    'parse_run_source',
    'recover_mcap',
    'run_parts',
    'RunSource',
    'SplitRecording',
]


@dataclass(frozen=True)
class RecordedTopic:
    """A channel of a recording: topic, ROS type, offered QoS text and message count."""

    topic: str
    type_name: str
    offered_qos: str
    message_count: int


@dataclass(frozen=True)
class RecordedMessage:
    """One recorded message: topic, type, log time (ns) and the serialized CDR bytes."""

    topic: str
    type_name: str
    log_time_ns: int
    data: bytes


#: What reading a truncated or corrupt record can raise (EndOfFile is an McapError).
_READ_ERRORS: tuple[type[BaseException], ...] = (
    McapError, EOFError, ValueError, RuntimeError, struct.error, KeyError, IndexError) + (
    (zstandard.ZstdError,) if zstandard is not None else ())


def _open(path: Path) -> BinaryIO:
    try:
        return open(path, 'rb')
    except OSError as err:
        raise RecordingError(f'cannot open the recording {str(path)!r}: '
                             f'{err.strerror or err}') from err


def _type_name(schema: Schema | None) -> str:
    return schema.name if schema is not None else ''


class RecordStream:
    """
    The records of an MCAP stream in file order, up to the first unreadable one.

    Iterating reads from the stream's current position (the magic bytes first) with CRCs
    checked, and stops at the end of the file or at the first record that is incomplete or
    damaged: :attr:`error` is then what reading it raised (None while none was raised).
    The stream's position is where reading stopped. :attr:`schemas` and :attr:`channels`
    hold the schema and channel records seen so far (the first of each id), so a message
    can be resolved as soon as it is yielded.
    """

    def __init__(self, stream: BinaryIO) -> None:
        """Read ``stream`` (open in binary mode) when iterated."""
        self.error: BaseException | None = None
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self._records = StreamReader(stream, validate_crcs=True).records

    def __iter__(self) -> Iterator[McapRecord]:
        """Yield the records; a read error ends the iteration and sets :attr:`error`."""
        while True:
            try:
                record = next(self._records)
            except StopIteration:
                return
            except _READ_ERRORS as err:
                self.error = err
                return
            if isinstance(record, Schema):
                self.schemas.setdefault(record.id, record)
            elif isinstance(record, Channel):
                self.channels.setdefault(record.id, record)
            yield record


@dataclass
class Recording:
    """
    What is known about a recording before its messages are read.

    complete: the file has its summary and footer (it was closed properly); problem: why
    it is incomplete or where reading failed (None while everything read fine); start_ns,
    end_ns: log times of the first and last readable message (None when there is none).
    """

    path: Path
    complete: bool
    topics: dict[str, RecordedTopic]
    metadata: dict[str, dict[str, str]]
    start_ns: int | None
    end_ns: int | None
    message_count: int
    problem: str | None = None
    #: Log time from which a complete file's data are damaged (None: intact as far as known).
    _damaged_from_ns: int | None = field(default=None, repr=False)

    def messages(self, topics: set[str] | None = None, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[RecordedMessage]:
        """
        Yield the messages of ``topics`` (None: all) with start_ns <= log time <= end_ns.

        Complete files: in log-time order. Incomplete files: in file order, up to the
        first unreadable record. A read error ends the iteration and sets :attr:`problem`.
        """
        if self.complete:
            yield from self._indexed(topics, start_ns, end_ns)
        else:
            yield from self._sequential(topics, start_ns, end_ns)

    def _indexed(self, topics: set[str] | None, start_ns: int | None, end_ns: int | None
                 ) -> Iterator[RecordedMessage]:
        if self._damaged_from_ns is not None:
            end_ns = (self._damaged_from_ns - 1 if end_ns is None
                      else min(end_ns, self._damaged_from_ns - 1))
            if start_ns is not None and start_ns > end_ns:
                return
        with _open(self.path) as stream:
            reader = SeekingReader(stream, validate_crcs=True)
            messages = reader.iter_messages(
                topics=None if topics is None else sorted(topics), starting_at=start_ns,
                ending_at=end_ns, log_time_order=True)
            while True:
                try:
                    schema, channel, message = next(messages)
                except StopIteration:
                    return
                except _READ_ERRORS as err:
                    self.problem = f'damaged data after the messages read so far: {err!r}'
                    return
                yield RecordedMessage(channel.topic, _type_name(schema), message.log_time,
                                      message.data)

    def _sequential(self, topics: set[str] | None, start_ns: int | None,
                    end_ns: int | None) -> Iterator[RecordedMessage]:
        with _open(self.path) as stream:
            # up to the end of the readable part (the problem is known already)
            records = RecordStream(stream)
            for record in records:
                if not isinstance(record, Message):
                    continue
                channel = records.channels.get(record.channel_id)
                if channel is None or (topics is not None and channel.topic not in topics):
                    continue
                if start_ns is not None and record.log_time < start_ns:
                    continue
                if end_ns is not None and record.log_time > end_ns:
                    continue
                yield RecordedMessage(channel.topic,
                                      _type_name(records.schemas.get(channel.schema_id)),
                                      record.log_time, record.data)


def _count_topic(topics: dict[str, RecordedTopic], found: RecordedTopic) -> None:
    """Add a topic to ``topics``; a topic met again (another channel, file) adds its count."""
    known = topics.get(found.topic)
    if known is not None:
        found = dataclasses.replace(known, message_count=known.message_count
                                    + found.message_count)
    topics[found.topic] = found


def _read_complete(path: Path) -> Recording | None:
    """Return the recording read through its summary, None when there is no usable one."""
    with _open(path) as stream:
        try:
            reader = SeekingReader(stream, validate_crcs=True)
            summary = reader.get_summary()
            if summary is None or summary.statistics is None or not summary.chunk_indexes:
                return None
            metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        except (*_READ_ERRORS, OSError):  # OSError: seeking before the start of a short file
            return None
        damaged = _first_damaged_chunk(stream, summary.chunk_indexes)
    stats = summary.statistics
    topics: dict[str, RecordedTopic] = {}
    for channel in summary.channels.values():
        _count_topic(topics, RecordedTopic(
            channel.topic, _type_name(summary.schemas.get(channel.schema_id)),
            channel.metadata.get('offered_qos_profiles', ''),
            stats.channel_message_counts.get(channel.id, 0)))
    count = stats.message_count
    start = stats.message_start_time if count else None
    end = stats.message_end_time if count else None
    problem = None
    damaged_from = None
    if damaged is not None:
        index, reason = damaged
        damaged_from = index.message_start_time
        before = [c.message_end_time for c in summary.chunk_indexes
                  if c.message_end_time < damaged_from]
        end = max(before) if before else None
        start = start if end is not None else None
        problem = (f'damaged chunk at byte {index.chunk_start_offset} ({reason}): messages '
                   f'from log time {damaged_from} ns on are not read')
    return Recording(path, True, topics, metadata, start, end, count, problem,
                     _damaged_from_ns=damaged_from)


def _first_damaged_chunk(stream: BinaryIO, indexes: list[Any]) -> tuple[Any, str] | None:
    """
    Return the first chunk (by log time) whose record does not match its index, and why.

    Only the chunk headers are read (a few bytes each). Damage inside the compressed data
    shows when the chunk is decompressed (its CRC or the decompressor fails).
    """
    damaged = []
    for index in indexes:
        stream.seek(index.chunk_start_offset)
        head = stream.read(1 + 8 + 8 + 8 + 8 + 4 + 4)
        reason = None
        if len(head) < 41:
            reason = 'cut short'
        else:
            opcode, length, start, end, size, _crc, name_length = struct.unpack('<BQQQQII', head)
            name = stream.read(name_length) if name_length < 64 else b''
            if opcode != 0x06 or length != index.chunk_length - 9:
                reason = 'not a chunk record where the index points'
            elif (start, end, size) != (
                    index.message_start_time, index.message_end_time, index.uncompressed_size):
                reason = 'its times or size differ from the index'
            elif name != index.compression.encode():
                reason = 'its compression differs from the index'
        if reason is not None:
            damaged.append((index, reason))
    if not damaged:
        return None
    return min(damaged, key=lambda item: item[0].message_start_time)


def _scan(path: Path) -> Recording:
    """Read an incomplete file sequentially up to its first unreadable record."""
    channels: dict[int, tuple[str, str]] = {}
    qos: dict[str, str] = {}
    counts: dict[str, int] = {}
    metadata: dict[str, dict[str, str]] = {}
    start = end = None
    total = 0
    problem = None
    footer = False
    with _open(path) as stream:
        records = RecordStream(stream)
        for record in records:
            if isinstance(record, Channel) and record.id not in channels:
                channels[record.id] = (record.topic,
                                       _type_name(records.schemas.get(record.schema_id)))
                qos.setdefault(record.topic, record.metadata.get('offered_qos_profiles', ''))
                counts.setdefault(record.topic, 0)
            elif isinstance(record, Metadata):
                metadata[record.name] = dict(record.metadata)
            elif isinstance(record, Message) and record.channel_id in channels:
                topic = channels[record.channel_id][0]
                counts[topic] += 1
                total += 1
                start = record.log_time if start is None else min(start, record.log_time)
                end = record.log_time if end is None else max(end, record.log_time)
            elif isinstance(record, Footer):
                footer = True
        if records.error is not None:
            err = records.error
            problem = (f'at byte {stream.tell()} of {path.stat().st_size}: '
                       f'{str(err) or type(err).__name__}')
    if total == 0 and not channels and problem is not None:
        raise RecordingError(f'{str(path)!r} is not a readable MCAP file: {problem}')
    if problem is None:
        problem = ('no summary: the writer did not finish the file' if footer else
                   'no footer: the file ends early, the writer did not finish it')
    else:
        problem = ('the file was not finished (truncated, or the writer was killed) or is '
                   f'damaged: reading stopped {problem}')
    topics = {topic: RecordedTopic(topic, type_name, qos.get(topic, ''), counts.get(topic, 0))
              for topic, type_name in channels.values()}
    return Recording(path, False, topics, metadata, start, end, total, problem, channels)


#: What names a recording: a file (the first of a split run), a directory, or a list of files.
RunSource = str | os.PathLike | Sequence[str | os.PathLike]


def _open_file(path: Path) -> Recording:
    """Open one file: through its index when complete, else its readable beginning."""
    with _open(path) as stream:
        magic = stream.read(8)
    if magic != b'\x89MCAP0\r\n':
        raise RecordingError(f'{str(path)!r} is not an MCAP file (wrong magic bytes)')
    recording = _read_complete(path)
    return recording if recording is not None else _scan(path)


def parse_run_source(text: str) -> RunSource:
    """Return the recording a text names (a ROS parameter): ``a.mcap,b.mcap`` is a list."""
    parts = [part.strip() for part in text.split(',') if part.strip()]
    return parts if len(parts) > 1 else text.strip()


def run_parts(source: RunSource) -> list[Path]:
    """
    Return the files of a recording in order.

    ``source`` is a list of files (taken as given), a directory (its ``.mcap`` files, the
    parts of each run in order) or one file: the first file of a run split by the recorder
    brings its parts ``<stem>_2.mcap``, ``<stem>_3.mcap``... along (as long as they exist
    and their ``cone_feeder_sim.part`` record names the same run).
    """
    return [part.path for part in _open_run(source)]


def _open_run(source: RunSource) -> list[Recording]:
    """Open every file of a recording once, in order (see :func:`run_parts`)."""
    if not isinstance(source, (str, os.PathLike)):
        paths = [Path(p) for p in source]
        if not paths:
            raise RecordingError('an empty list of recordings')
        return [_open_file(path) for path in paths]
    path = Path(source)
    if path.is_dir():
        files = sorted(path.glob('*.mcap'))
        if not files:
            raise RecordingError(f'{str(path)!r} holds no .mcap file')
        opened: list[Recording] = []
        for first in (f for f in files
                      if not any(part_number(g, f) for g in files if g != f)):
            opened += [r for r in _open_run(first) if r.path not in {o.path for o in opened}]
        claimed = {r.path for r in opened}
        return opened + [_open_file(f) for f in files if f not in claimed]
    parts = [_open_file(path)]
    run = parts[0].metadata.get(PART_METADATA_NAME, {}).get('run')
    while run is not None:
        following = part_path(path, len(parts) + 1)
        if not following.is_file():
            break
        try:
            part = _open_file(following)
        except RecordingError:
            break
        if part.metadata.get(PART_METADATA_NAME, {}).get('run') != run:
            break
        parts.append(part)
    return parts


class SplitRecording:
    """
    A recording in several files, read as one: the parts' messages one after the other.

    Same interface as :class:`Recording`: ``path`` is the first file, ``paths`` all of
    them; ``metadata`` merges the parts' records (the end record is the last part's).
    """

    def __init__(self, parts: list[Recording]) -> None:
        """Combine opened parts (in order)."""
        self.parts = parts
        self.path = parts[0].path
        self.paths = [part.path for part in parts]
        self.complete = all(part.complete for part in parts)
        self.topics: dict[str, RecordedTopic] = {}
        for part in parts:
            for info in part.topics.values():
                _count_topic(self.topics, info)
        self.metadata: dict[str, dict[str, str]] = {}
        for part in parts:
            self.metadata.update(part.metadata)
        starts = [p.start_ns for p in parts if p.start_ns is not None]
        ends = [p.end_ns for p in parts if p.end_ns is not None]
        self.start_ns = starts[0] if starts else None
        self.end_ns = ends[-1] if ends else None
        self.message_count = sum(part.message_count for part in parts)

    @property
    def problem(self) -> str | None:
        """Return the first part's problem, naming the part (None if all read fine)."""
        for part in self.parts:
            if part.problem:
                return f'{part.path.name}: {part.problem}'
        return None

    def messages(self, topics: set[str] | None = None, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[RecordedMessage]:
        """Yield the messages of every part in turn (see :meth:`Recording.messages`)."""
        for part in self.parts:
            if start_ns is not None and part.end_ns is not None and part.end_ns < start_ns:
                continue
            if end_ns is not None and part.start_ns is not None and part.start_ns > end_ns:
                return
            yield from part.messages(topics, start_ns, end_ns)


def open_recording(source: RunSource) -> Recording | SplitRecording:
    """
    Open a recording: one file, or every part of a split run (see :func:`run_parts`).

    Complete files are read through their index, others up to their first unreadable
    record. Raises RecordingError when a file cannot be opened or does not start as MCAP.
    """
    parts = _open_run(source)
    return parts[0] if len(parts) == 1 else SplitRecording(parts)


def recover_mcap(source: str | os.PathLike, destination: str | os.PathLike) -> int:
    """
    Copy the readable part of a possibly truncated MCAP file into a complete one.

    Records are read in order until the first one that is incomplete or corrupt (a chunk
    only counts once it decompresses and its CRC matches); schemas, channels, messages,
    metadata and attachments read before that are written to ``destination`` with summary
    and footer. Return the number of messages recovered.
    """
    source_path = Path(source)
    with _open(source_path) as source_stream:
        records = RecordStream(source_stream)
        header = next(iter(records), None)
        if not isinstance(header, Header):
            reason = repr(records.error) if records.error is not None else 'no MCAP header'
            raise RecordingError(f'{str(source_path)!r} is not an MCAP file: {reason}')
        with _open_for_writing(Path(destination)) as stream:
            writer = Writer(stream, compression=CompressionType.ZSTD)
            writer.start(profile=header.profile, library=f'{LIBRARY} (recovered)')
            count = _copy_records(records, writer)
            writer.finish()
    return count


def _copy_records(records: RecordStream, writer: Writer) -> int:
    """Copy records to ``writer`` until the stream ends or a record is unreadable."""
    schema_ids: dict[int, int] = {0: 0}
    channel_ids: dict[int, int] = {}
    count = 0
    for record in records:
        if isinstance(record, Schema):
            if record.id not in schema_ids:
                schema_ids[record.id] = writer.register_schema(
                    record.name, record.encoding, record.data)
        elif isinstance(record, Channel):
            if record.id not in channel_ids and record.schema_id in schema_ids:
                channel_ids[record.id] = writer.register_channel(
                    record.topic, record.message_encoding, schema_ids[record.schema_id],
                    dict(record.metadata))
        elif isinstance(record, Message):
            channel_id = channel_ids.get(record.channel_id)
            if channel_id is not None:
                writer.add_message(
                    channel_id, record.log_time, record.data, record.publish_time,
                    record.sequence)
                count += 1
        elif isinstance(record, Metadata):
            writer.add_metadata(record.name, dict(record.metadata))
        elif isinstance(record, Attachment):
            writer.add_attachment(
                record.create_time, record.log_time, record.name, record.media_type,
                record.data)
    return count
