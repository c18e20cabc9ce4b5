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
Crash-tolerant ROS 2 MCAP recording without rclpy.

:class:`McapRecorder` writes the ``ros2`` MCAP profile the way rosbag2 does:
schemas with encoding ``ros2msg`` holding the complete definition text (see
:mod:`cone_feeder_sim.formats.msgtypes`), channels with message encoding ``cdr`` and
the ``offered_qos_profiles`` metadata (YAML), and messages encoded with
:mod:`cone_feeder_sim.formats.cdr`. Log and publish times are the caller's
nanoseconds.

Data are written in chunks that are finished (``mcap.writer.Writer.flush``,
public since mcap 1.2) and pushed to the OS at least every
``flush_interval_s`` of wall-clock time (checked on each write, or by
:meth:`McapRecorder.maybe_flush`) and whenever the messages of a chunk exceed
``chunk_size`` bytes (the recorder decides when chunks end, not the Writer, so
that every finished chunk also reaches the OS). After a SIGKILL the file is
therefore a valid MCAP prefix that streaming readers read up to the last
complete chunk; ``cone-feeder-sim recover`` (:func:`~cone_feeder_sim.formats.mcap_reader.
recover_mcap`) turns such a file into a complete one (with summary and footer) that indexed
readers such as rosbags accept.
"""

import collections.abc
import os
import pathlib
import threading
import time
from types import TracebackType
from typing import Any, BinaryIO, Self

from mcap.exceptions import McapError
from mcap.writer import CompressionType, Writer

from .cdr import CdrCodec, CdrError, default_codec
from .msgtypes import MessageDefinitionError, normalize_type_name
from .topics import QosLike, QosProfile
from ..errors import RecordingError


__all__ = [
    'COMPRESSIONS',
    'DEFAULT_FLUSH_INTERVAL_S',
    'McapRecorder',
]

DEFAULT_FLUSH_INTERVAL_S = 1.0
DEFAULT_CHUNK_SIZE = 1024 * 1024
PROFILE = 'ros2'
SCHEMA_ENCODING = 'ros2msg'
MESSAGE_ENCODING = 'cdr'
LIBRARY = 'cone_feeder_sim'

#: Bytes a message adds to the file besides its data: its Message record's opcode, length,
#: ids and times (31), and its entry in the chunk's MessageIndex (16: log time, offset).
_MESSAGE_RECORD_OVERHEAD = 31 + 16
#: Bytes of a Schema and of a Channel record besides their strings and data.
_SCHEMA_RECORD_OVERHEAD = 25
_CHANNEL_RECORD_OVERHEAD = 60
#: Chunk size handed to mcap's Writer: chunks are ended by the recorder instead.
_NEVER = 2 ** 62

#: Chunk compressions of a recording: zstd (smallest files), lz4 (least CPU) or none.
COMPRESSIONS: dict[str, CompressionType] = {
    'zstd': CompressionType.ZSTD,
    'lz4': CompressionType.LZ4,
    'none': CompressionType.NONE,
}


def _close_stream(stream: BinaryIO) -> None:
    """Close a stream whose buffered bytes cannot be written (they are dropped)."""
    try:
        stream.close()
    except OSError:
        pass


def _open_for_writing(path: pathlib.Path) -> BinaryIO:
    try:
        return open(path, 'wb')
    except OSError as err:
        reason = err.strerror or str(err)
        raise RecordingError(f'cannot open MCAP file {str(path)!r} for writing: {reason}') from err


class McapRecorder:
    """
    Context-managed writer of a ROS 2 MCAP file with bounded data loss on a crash.

    ``qos`` maps topics to :class:`QosProfile` (or mappings of its fields);
    topics not listed get the default profile. ``compression`` of chunks is
    ``zstd``, ``lz4`` or ``none``. ``clock`` returns seconds and is only used
    to time flushes. Flushing hands data to the OS, which survives a SIGKILL of
    the process; ``fsync=True`` also forces it to disk (power loss) on every
    flush. The recorder is thread-safe.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        compression: str = 'zstd',
        qos: collections.abc.Mapping[str, QosLike] | None = None,
        codec: CdrCodec | None = None,
        fsync: bool = False,
        clock: collections.abc.Callable[[], float] = time.monotonic,
    ) -> None:
        """Create (truncate) the file at ``path`` and write the MCAP header."""
        if not flush_interval_s > 0:
            raise RecordingError(f'flush_interval_s must be > 0, got {flush_interval_s!r}')
        if chunk_size <= 0:
            raise RecordingError(f'chunk_size must be > 0, got {chunk_size!r}')
        if compression not in COMPRESSIONS:
            raise RecordingError(
                f'compression must be one of {", ".join(COMPRESSIONS)}, got {compression!r}')
        self._qos = {topic: QosProfile.from_value(value) for topic, value in (qos or {}).items()}
        self._path = pathlib.Path(path)
        self._codec = codec if codec is not None else default_codec()
        self._flush_interval_s = float(flush_interval_s)
        self._fsync = fsync
        self._clock = clock
        self._lock = threading.RLock()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._channel_types: dict[str, str] = {}
        self._sequences: dict[int, int] = {}
        self._message_count = 0
        self._closed = False
        self._stream = _open_for_writing(self._path)
        try:
            self._writer = Writer(
                self._stream, chunk_size=_NEVER, compression=COMPRESSIONS[compression])
            self._writer.start(profile=PROFILE, library=LIBRARY)
            self._flush_stream()
        except BaseException as err:
            _close_stream(self._stream)
            if isinstance(err, McapError):  # e.g. the compression library is missing
                raise RecordingError(
                    f'cannot start MCAP file {str(self._path)!r}: {err}') from err
            if isinstance(err, OSError):  # e.g. no space left on the device
                raise RecordingError(f'cannot write MCAP file {str(self._path)!r}: '
                                     f'{err.strerror or err}') from err
            raise
        self._chunk_size = chunk_size
        self._pending_bytes = 0
        self._chunk_messages = 0
        self._last_flush = self._clock()

    @property
    def path(self) -> pathlib.Path:
        """Return the path of the file being written."""
        return self._path

    @property
    def size_bytes(self) -> int:
        """Return the bytes in the file so far plus the open chunk's (uncompressed, indexed)."""
        with self._lock:
            return self._stream.tell() + self._pending_bytes

    @property
    def closed(self) -> bool:
        """Return whether :meth:`close` has been called."""
        return self._closed

    @property
    def message_count(self) -> int:
        """Return the number of messages written so far."""
        return self._message_count

    def _check_open(self) -> None:
        if self._closed:
            raise RecordingError(f'recorder of {str(self._path)!r} is closed')

    def add_topic(self, topic: str, type_name: str, qos: QosLike = None) -> int:
        """
        Register ``topic`` with ``type_name`` (once) and return its channel id.

        ``qos`` overrides the profile given at construction for this topic.
        Registering a topic again with the same type returns the same channel.
        """
        with self._lock:
            self._check_open()
            canonical = normalize_type_name(type_name)
            known = self._channels.get(topic)
            if known is not None:
                if self._channel_types[topic] != canonical:
                    raise RecordingError(
                        f'topic {topic!r} is recorded as {self._channel_types[topic]}, '
                        f'not {canonical}')
                return known
            profile = QosProfile.from_value(qos) if qos is not None else self._qos.get(
                topic, QosProfile())
            schema_id = self._schemas.get(canonical)
            if schema_id is None:
                try:
                    text = self._codec.registry.full_text(canonical)
                except MessageDefinitionError as err:
                    raise RecordingError(f'cannot record topic {topic!r}: {err}') from err
                data = text.encode('utf-8')
                schema_id = self._writer.register_schema(
                    name=canonical, encoding=SCHEMA_ENCODING, data=data)
                self._schemas[canonical] = schema_id
                # the schema goes into the open chunk: it counts towards the file's size
                self._pending_bytes += len(data) + len(canonical) + _SCHEMA_RECORD_OVERHEAD
            qos_yaml = profile.to_yaml()
            channel_id = self._writer.register_channel(
                topic=topic, message_encoding=MESSAGE_ENCODING, schema_id=schema_id,
                metadata={'offered_qos_profiles': qos_yaml})
            self._pending_bytes += len(topic) + len(qos_yaml) + _CHANNEL_RECORD_OVERHEAD
            self._channels[topic] = channel_id
            self._channel_types[topic] = canonical
            self._sequences[channel_id] = 0
            return channel_id

    def write(
        self, topic: str, type_name: str, message: Any, log_time_ns: int,
        publish_time_ns: int | None = None
    ) -> None:
        """
        Encode ``message`` (mapping or object) as ``type_name`` and record it on ``topic``.

        ``publish_time_ns`` defaults to ``log_time_ns``.
        """
        try:
            data = self._codec.encode(type_name, message)
        except CdrError as err:
            raise RecordingError(f'cannot record a message on {topic!r}: {err}') from err
        self.write_serialized(topic, type_name, data, log_time_ns, publish_time_ns)

    def write_serialized(
        self, topic: str, type_name: str, data: bytes, log_time_ns: int,
        publish_time_ns: int | None = None
    ) -> None:
        """Record already CDR-encoded ``data`` of ``type_name`` on ``topic``."""
        log_time = int(log_time_ns)
        publish_time = log_time if publish_time_ns is None else int(publish_time_ns)
        if not 0 <= log_time < 2 ** 64 or not 0 <= publish_time < 2 ** 64:
            raise RecordingError(
                f'times must be unsigned 64-bit nanoseconds, got {log_time}, {publish_time}')
        with self._lock:
            channel_id = self.add_topic(topic, type_name)
            sequence = self._sequences[channel_id]
            self._sequences[channel_id] = (sequence + 1) & 0xFFFFFFFF
            self._writer.add_message(
                channel_id=channel_id, log_time=log_time, data=data,
                publish_time=publish_time, sequence=sequence)
            self._message_count += 1
            self._chunk_messages += 1
            self._pending_bytes += len(data) + _MESSAGE_RECORD_OVERHEAD
            if self._pending_bytes >= self._chunk_size:
                self.flush()
                return
            self.maybe_flush()

    def add_metadata(self, name: str, data: collections.abc.Mapping[str, str]) -> None:
        """Write a metadata record ``name`` with string keys and values."""
        if not isinstance(name, str) or not all(
                isinstance(key, str) and isinstance(value, str) for key, value in data.items()):
            raise RecordingError('metadata name, keys and values must all be str')
        with self._lock:
            self._check_open()
            self._writer.add_metadata(name, dict(data))
            self._flush_stream()

    def maybe_flush(self) -> bool:
        """Flush if ``flush_interval_s`` has passed since the last flush; return whether it did."""
        with self._lock:
            if self._closed or self._clock() - self._last_flush < self._flush_interval_s:
                return False
            self.flush()
            return True

    def flush(self) -> None:
        """Finish the current chunk and push everything written so far to the OS."""
        with self._lock:
            self._check_open()
            self._writer.flush()
            self._flush_stream()
            if self._chunk_messages:  # a chunk without messages stays open (mcap's Writer)
                self._pending_bytes = 0
                self._chunk_messages = 0
            self._last_flush = self._clock()

    def _flush_stream(self) -> None:
        self._stream.flush()
        if self._fsync:
            os.fsync(self._stream.fileno())

    def close(self) -> None:
        """Finish the file (last chunk, summary, statistics, footer); idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self._writer.finish()
                self._flush_stream()
            finally:
                self._stream.close()

    def __enter__(self) -> Self:
        """Return the recorder itself."""
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None,
        traceback: TracebackType | None
    ) -> None:
        """Close the recorder, completing the file even when an exception is propagating."""
        self.close()
