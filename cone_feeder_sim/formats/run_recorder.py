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
The MCAP recording of a live run: written by a thread, split into parts, never in the way.

Like rosbag2's ``--max-bag-size`` / ``--max-bag-duration``, :class:`RunRecorder` goes on in
the next file when the current one reaches :attr:`RecordingLimits.max_file_size` bytes or
:attr:`RecordingLimits.max_file_duration_ns` of log time: the first file is the path given,
the next ones ``<stem>_2.mcap``, ``<stem>_3.mcap``... Each part is a complete MCAP file with
every channel, the run's metadata and a ``cone_feeder_sim.part`` record (run id and part
number) that :func:`~cone_feeder_sim.formats.mcap_reader.run_parts` uses to find the parts
of a run. An existing file is never overwritten.

Nothing here stops the caller: a write error (a full disk, a removed directory) or free
space falling below :attr:`RecordingLimits.min_free_bytes` ends the recording, with the
current file closed as well as it can be, and :attr:`RunRecorder.error` says why; later
messages are dropped. Only the start raises (:class:`~cone_feeder_sim.errors.RecordingError`).
"""

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
import os
from pathlib import Path
import queue
import shutil
import threading
import time
from typing import Any
import uuid

from .mcap_writer import DEFAULT_CHUNK_SIZE, McapRecorder
from .topics import MessageRecord, QosProfile
from ..errors import RecordingError

__all__ = ['END_METADATA_NAME', 'PART_METADATA_NAME', 'RecordingLimits', 'RunRecorder',
           'make_parent_dir', 'part_number', 'part_path']

#: Name of the metadata record that tells which run and which part a file is.
PART_METADATA_NAME = 'cone_feeder_sim.part'
#: Name of the metadata record written when a recording is closed (absent after a crash).
END_METADATA_NAME = 'cone_feeder_sim.end'
#: Wall-clock seconds after which written data are in a finished chunk handed to the OS.
FLUSH_INTERVAL_S = 0.5
#: Queued bytes beyond which the caller waits for the writer (nothing is dropped).
MAX_BACKLOG_BYTES = 256 * 1024 * 1024
#: How often (wall-clock s) the writer thread wakes up when nothing arrives.
_POLL_S = 0.1
#: How often (wall-clock s) the free space is checked.
_SPACE_CHECK_S = 1.0
#: Token that only wakes the writer thread.
_WAKE = object()


@dataclass(frozen=True)
class RecordingLimits:
    """
    When a recording goes on in a new file, and when it stops.

    max_file_size (bytes) and max_file_duration_ns (log time): 0 = no limit; a file is ended
    before the message that would take it past either (approximately for the size: data
    are compressed when a chunk ends). min_free_bytes: the recording stops, its file
    closed, when less than this is free on the file's device (0 = no guard).
    """

    max_file_size: int = 0
    max_file_duration_ns: int = 0
    min_free_bytes: int = 0


def part_path(first: Path, part: int) -> Path:
    """Return the path of part ``part`` (1-based) of a recording whose first file is ``first``."""
    return first if part == 1 else first.with_name(f'{first.stem}_{part}{first.suffix}')


def part_number(first: Path, candidate: Path) -> int | None:
    """Return n when ``candidate`` is named as part n >= 2 of ``first``, else None."""
    head, _, tail = candidate.stem.rpartition('_')
    if candidate.parent != first.parent or candidate.suffix != first.suffix:
        return None
    return int(tail) if head == first.stem and tail.isdigit() and int(tail) >= 2 else None


def _free_bytes(directory: Path) -> int:
    return shutil.disk_usage(directory).free


def make_parent_dir(path: Path) -> None:
    """Create the directory of a recording (RecordingError naming both if impossible)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise RecordingError(
            f'cannot create the directory {str(path.parent)!r} for the recording {str(path)!r}: '
            f'{err.strerror or err}') from err


class RunRecorder:
    """
    The MCAP recorder of a live node: cheap to call from the timer, written by a thread.

    ``topics``: (resolved topic, type name, QoS) of every channel, registered at the start of
    every part so that every topic is in each file even when nothing was sent on it.
    ``metadata``: records written at the start of every part. :meth:`write` only queues the
    bytes; the writer thread writes them and finishes a chunk at least every
    ``flush_interval_s`` (wall clock), so a SIGKILL loses about that much. When the writer
    falls ``max_backlog_bytes`` behind, :meth:`write` waits (the simulation slows down;
    nothing is dropped). Thread-safe.
    """

    def __init__(self, path: str | os.PathLike, topics: Iterable[tuple[str, str, QosProfile]],
                 metadata: Mapping[str, Mapping[str, str]], *,
                 limits: RecordingLimits = RecordingLimits(),
                 flush_interval_s: float = FLUSH_INTERVAL_S, compression: str = 'zstd',
                 chunk_size: int = DEFAULT_CHUNK_SIZE,
                 max_backlog_bytes: int = MAX_BACKLOG_BYTES) -> None:
        """
        Create the first file (and missing directories); write channels and metadata.

        Raises RecordingError when the file or one of its part names exists, the place
        cannot be written or has less than ``limits.min_free_bytes`` free.
        """
        self._first = Path(path)
        if self._first.exists() and not self._first.is_file():
            raise RecordingError(f'{str(self._first)!r} is not a regular file')
        make_parent_dir(self._first)
        taken = [self._first] if self._first.exists() else []
        taken += sorted(p for p in self._first.parent.glob(f'{self._first.stem}_*')
                        if part_number(self._first, p))
        if taken:
            raise RecordingError(f'{str(taken[0])!r} exists: a recording never overwrites a '
                                 'file (choose another record_path or move the old run)')
        self._limits = limits
        self._topics = list(topics)
        self._metadata = {name: dict(data) for name, data in metadata.items()}
        self._options = {'flush_interval_s': flush_interval_s, 'compression': compression,
                         'chunk_size': chunk_size}
        self._run_id = uuid.uuid4().hex
        self._paths: list[Path] = []
        self._file_start_ns: int | None = None
        self._recorder = self._open_part()
        try:
            self._check_space()
        except RecordingError:
            _close_quietly(self._recorder)
            self._first.unlink(missing_ok=True)  # the file just made, holding no message
            raise
        # The caller's thread takes no lock that the writer thread needs: the only channel
        # is a SimpleQueue (put is atomic and safe to interrupt), and each byte counter has
        # one writer. A signal (SIGINT, SIGTERM) raised in the caller's thread while it held
        # a lock, including the one inside threading.Event, can leave that lock held (the
        # exception can land between acquiring it and entering the with block), and close()
        # would then wait forever for a writer that can never take it.
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._queued_bytes = 0  # written only by the producer
        self._done_bytes = 0  # written only by the writer thread
        self._max_backlog = max_backlog_bytes
        self._closed = False
        self._written = 0
        self._error: BaseException | None = None
        self._next_space_check = time.monotonic() + _SPACE_CHECK_S
        self._thread = threading.Thread(target=self._run, name='mcap_writer', daemon=True)
        self._thread.start()

    @property
    def path(self) -> Path:
        """Return the path of the first file."""
        return self._first

    @property
    def paths(self) -> tuple[Path, ...]:
        """Return the paths of the files written so far, in order."""
        return tuple(self._paths)

    @property
    def error(self) -> BaseException | None:
        """Return the error that stopped the recording, if any."""
        return self._error

    @property
    def message_count(self) -> int:
        """Return the number of messages written so far, over all files."""
        return self._written

    @property
    def closed(self) -> bool:
        """Tell whether :meth:`close` has run."""
        return self._closed

    # ------------------------------------------------------------------ parts

    def _check_space(self) -> None:
        """Raise RecordingError when the destination has less free space than the guard."""
        if not self._limits.min_free_bytes:
            return
        try:
            free = _free_bytes(self._first.parent)
        except OSError as err:
            raise RecordingError(f'cannot check the free space of {str(self._first.parent)!r}: '
                                 f'{err.strerror or err}') from err
        if free < self._limits.min_free_bytes:
            raise RecordingError(
                f'only {free / 1e6:.1f} MB free on the device of {str(self._first.parent)!r}, '
                f'less than the {self._limits.min_free_bytes / 1e6:.1f} MB kept free '
                '(record_min_free_space): recording stopped')

    def _open_part(self) -> McapRecorder:
        """Start the next file: channels, the run's metadata and the part record."""
        part = len(self._paths) + 1
        path = part_path(self._first, part)
        if part > 1 and path.exists():
            raise RecordingError(f'{str(path)!r} exists: not overwritten; recording stopped')
        recorder = McapRecorder(path, **self._options)
        try:
            for topic, type_name, qos in self._topics:
                recorder.add_topic(topic, type_name, qos)
            for name, data in self._metadata.items():
                recorder.add_metadata(name, data)
            recorder.add_metadata(PART_METADATA_NAME, {'run': self._run_id, 'part': str(part)})
            recorder.flush()
        except BaseException as err:
            _close_quietly(recorder)
            if isinstance(err, OSError):
                raise RecordingError(f'cannot write {str(path)!r}: '
                                     f'{err.strerror or err}') from err
            raise
        self._paths.append(path)
        self._file_start_ns = None
        return recorder

    def _split_due(self, log_time_ns: int, size: int) -> bool:
        limits = self._limits
        if self._file_start_ns is None:
            return False  # every file holds at least one message
        if limits.max_file_duration_ns and (
                log_time_ns - self._file_start_ns >= limits.max_file_duration_ns):
            return True
        return bool(limits.max_file_size) and (
            self._recorder.size_bytes + size > limits.max_file_size)

    # ------------------------------------------------------------------ writing

    def write(self, topic: str, type_name: str, data: bytes, log_time_ns: int) -> None:
        """Queue a serialized message for the file; log and publish time = log_time_ns."""
        if self._closed or self._error is not None:
            return
        while (self._queued_bytes - self._done_bytes > self._max_backlog
               and self._error is None and self._thread.is_alive()):
            time.sleep(_POLL_S / 20)
        self._queued_bytes += len(data)
        self._queue.put((topic, type_name, data, log_time_ns))

    def hook(self, record: MessageRecord) -> None:
        """Queue a message of the node (its message hook); log time = its simulation time."""
        self.write(record.topic, record.type_name, record.data, record.stamp_ns)

    def maybe_flush(self) -> None:
        """Wake the writer so that a due flush happens even when no message arrives."""
        self._queue.put(_WAKE)

    def _next_batch(self) -> tuple[list[tuple[str, str, bytes, int]], bool]:
        """Return what is queued (waiting up to a poll period for it) and whether to stop."""
        batch: list[tuple[str, str, bytes, int]] = []
        stop = False
        try:
            item = self._queue.get(timeout=_POLL_S)
        except queue.Empty:
            return batch, stop
        while True:
            if item is None:
                stop = True
            elif item is not _WAKE:
                batch.append(item)
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                return batch, stop

    def _write_batch(self, batch: list[tuple[str, str, bytes, int]]) -> None:
        for topic, type_name, data, log_time in batch:
            if self._split_due(log_time, len(data)):
                _close_quietly(self._recorder)
                self._recorder = self._open_part()
            self._recorder.write_serialized(topic, type_name, data, log_time)
            if self._file_start_ns is None:
                self._file_start_ns = log_time
            self._written += 1
            self._done_bytes += len(data)
        self._recorder.maybe_flush()
        now = time.monotonic()
        if now >= self._next_space_check:
            self._next_space_check = now + _SPACE_CHECK_S
            self._check_space()

    def _run(self) -> None:
        while True:
            batch, stop = self._next_batch()
            if self._error is None:
                try:
                    self._write_batch(batch)
                except Exception as exc:  # noqa: B902 - kept and reported by the caller
                    self._error = exc
                    _close_quietly(self._recorder)  # what was written stays readable
            else:
                self._done_bytes += sum(len(item[2]) for item in batch)
            if stop:
                return

    def close(self, end_metadata: Mapping[str, str] | None = None) -> None:
        """
        Write what is queued, the end metadata, summary and footer; idempotent.

        Never raises: a failure to finish the file is kept in :attr:`error`.
        """
        if self._closed:
            return
        self._closed = True
        self._queue.put(None)
        self._thread.join()
        try:
            if end_metadata is not None and self._error is None:
                self._recorder.add_metadata(END_METADATA_NAME, {
                    **end_metadata, 'messages': str(self._written),
                    'parts': str(len(self._paths))})
        except Exception as exc:  # noqa: B902 - a full disk at the very end
            self._error = self._error or exc
        error = _close_quietly(self._recorder)
        self._error = self._error or error


def _close_quietly(recorder: McapRecorder) -> BaseException | None:
    """Close a file as well as possible; return the error instead of raising it."""
    try:
        recorder.close()
    except Exception as exc:  # noqa: B902 - the recording ends either way
        return exc
    return None
