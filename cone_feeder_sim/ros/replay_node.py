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
The ROS 2 node ``replay_node``: republishes a recorded run with its recorded timing.

Run it with ``ros2 run cone_feeder_sim replay_node --ros-args -p path:=run.mcap -p rate:=1.0
-p loop:=false`` (or ``replay_node`` / ``python -m cone_feeder_sim.ros.replay_node`` in a
virtual environment with the ``ros-jazzy-*`` wheels).

The recorded topics are published under their recorded (absolute) names with the recorded
types and the recorded QoS (``offered_qos_profiles``: history, depth, reliability,
durability), as the recorded bytes: nothing is decoded or re-encoded. A message with log
time ``L`` is published ``(L - start) / rate`` wall-clock seconds after the replay began,
where ``start`` is the log time of the first message plus ``start_offset``. Messages a
sim_node received (its commands, listed in the recording's metadata) are left out unless
``include_inputs`` is true, so a replay does not drive a running simulator.

Parameters (read at the start): ``path`` (MCAP file, required); ``rate`` (> 0, default 1.0);
``loop`` (start over at the end); ``publish_clock`` (publish ``/clock`` with the log time
of the messages, instead of a recorded ``/clock``); ``start_offset`` and ``stop_offset`` (s
from the first message; ``stop_offset`` 0 = to the end); ``topics`` (only these; empty:
all); ``include_inputs``; ``delay`` (wall-clock s before the first message, to let
subscribers connect); ``progress_period`` (wall-clock s between progress reports in the log
and on ``/diagnostics``, status ``<node>: replay``).

A file that was not finished (the recorder was killed) or is damaged is replayed up to its
first unreadable record, with a warning that says so; a file that is not MCAP, or has no
readable message, is refused with an error and exit status 1. Without ``loop`` the node
exits when the last message is out.
"""

from collections.abc import Callable
import importlib
import json
import sys
import time
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.parameter import Parameter
from rclpy.task import Future
from rosgraph_msgs.msg import Clock as ClockMessage

from .guarded_node import GuardedNode, run_node
from .parameters import declare, ParamSpec, warn_unknown_parameters
from .qos import rclpy_qos
from ..errors import ConeFeederError, ParameterError
from ..formats.mcap_reader import (
    open_recording, parse_run_source, RecordedMessage, Recording, SplitRecording)
from ..formats.runlog import METADATA_NAME
from ..formats.topics import qos_from_yaml, TOPICS
from ..physics.params import Limit

__all__ = ['ReplayNode', 'main', 'message_class']

NODE_NAME = 'replay_node'
#: Most messages published in one timer callback (the executor gets a turn in between).
_BATCH = 500
#: Shortest re-arm period of the play timer (ns).
_MIN_PERIOD_NS = 50_000


def message_class(type_name: str) -> Any:
    """Return the rclpy message class of 'pkg/msg/Type' (ConeFeederError if not installed)."""
    parts = type_name.split('/')
    if len(parts) == 2:
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3 or not all(parts):
        raise ConeFeederError(f'not a ROS message type name: {type_name!r}')
    try:
        return getattr(importlib.import_module(f'{parts[0]}.{parts[1]}'), parts[2])
    except (ImportError, AttributeError) as exc:
        raise ConeFeederError(f'message type {type_name} is not installed: {exc}') from exc


def _ns_time(ns: int) -> Time:
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


class ReplayNode(GuardedNode):
    """Republish a recording with its timing; see the module documentation."""

    def __init__(self, clock_ns: Callable[[], int] = time.monotonic_ns,
                 **kwargs: Any) -> None:
        """
        Read the parameters, open the recording and create the publishers.

        clock_ns: the steady wall clock (ns) the timing follows (the tests' is made up).
        """
        self._clock_ns = clock_ns
        super().__init__(NODE_NAME, **kwargs)

    def _declare(self, name: str, default: Any, description: str,
                 limit: Limit | None = None) -> Any:
        return declare(self, ParamSpec(name, default, description, limit=limit)).value

    def _setup(self) -> None:
        path = self._declare('path', '', 'MCAP file to replay (required)')
        self._rate = float(self._declare(
            'rate', 1.0, 'replay speed: recorded seconds per wall-clock second',
            Limit(0.0, 1000.0, '', lo_open=True)))
        self._loop = bool(self._declare('loop', False, 'start over at the end'))
        publish_clock = bool(self._declare(
            'publish_clock', False, 'publish /clock with the log times (a recorded /clock is '
            'then left out)'))
        start_offset = float(self._declare(
            'start_offset', 0.0, 'start this many s after the first message',
            Limit(0.0, 1.0e9, 's')))
        stop_offset = float(self._declare(
            'stop_offset', 0.0, 'stop this many s after the first message; 0: at the end',
            Limit(0.0, 1.0e9, 's')))
        topics = self._declare('topics', Parameter.Type.STRING_ARRAY,
                               'replay only these topics; empty: all')
        include_inputs = bool(self._declare(
            'include_inputs', False, 'also replay the commands the recorded node received'))
        delay = float(self._declare('delay', 0.0, 'wall-clock s before the first message',
                                    Limit(0.0, 3600.0, 's')))
        self._progress_period = float(self._declare(
            'progress_period', 1.0, 'wall-clock s between progress reports',
            Limit(0.05, 3600.0, 's')))
        warn_unknown_parameters(self)
        if not path:
            raise ParameterError('parameter path is required: the MCAP file to replay')
        if not self._rate > 0.0:
            raise ParameterError(f'rate must be > 0, got {self._rate:g}')
        if stop_offset and stop_offset <= start_offset:
            raise ParameterError(f'stop_offset = {stop_offset:g} s must be after start_offset '
                                 f'= {start_offset:g} s (or 0: to the end)')

        recording = open_recording(parse_run_source(path))
        self._recording = recording
        log = self.get_logger()
        if not recording.complete:
            log.warning(f'{path} is incomplete or damaged ({recording.problem}); replaying its '
                        f'readable part: {recording.message_count} messages')
        elif recording.problem:
            log.warning(f'{path} is damaged ({recording.problem}); replaying what comes before')
        self._problem = recording.problem
        if recording.start_ns is None or recording.end_ns is None:
            raise ConeFeederError(f'{path} has no readable message to replay')
        first = recording.start_ns
        self._start_ns = first + int(round(start_offset * 1e9))
        self._end_ns = (first + int(round(stop_offset * 1e9)) if stop_offset
                        else recording.end_ns)
        self._end_ns = min(self._end_ns, recording.end_ns)
        if self._start_ns > recording.end_ns:
            raise ParameterError(
                f'start_offset = {start_offset:g} s is past the end of the recording '
                f'({(recording.end_ns - first) * 1e-9:.6f} s after its first message)')

        selected = self._select(recording, list(topics or []), include_inputs, publish_clock)
        self._outputs: dict[str, Any] = {}
        for topic in sorted(selected):
            info = recording.topics[topic]
            try:
                msg_type = message_class(info.type_name)
            except ConeFeederError as exc:
                log.warning(f'topic {topic} left out: {exc}')
                continue
            self._outputs[topic] = self.create_publisher(
                msg_type, topic, rclpy_qos(qos_from_yaml(info.offered_qos)))
        if not self._outputs:
            raise ConeFeederError(f'{path}: no topic to replay')
        self._clock_pub = (self.create_publisher(ClockMessage, '/clock',
                                                 rclpy_qos(TOPICS['/clock'].qos))
                           if publish_clock else None)
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics',
                                               rclpy_qos(TOPICS['/diagnostics'].qos))

        self.done = Future()
        self.published = 0
        self.passes = 0
        self._last_clock: int | None = None
        self._position_ns = self._start_ns
        self._iter: Any = iter(())
        self._next: RecordedMessage | None = None
        self._wall0 = 0
        self._started = time.monotonic()
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._begin_pass(delay)
        self._play_timer = self.create_timer(max(delay, 1e-4), self._on_play,
                                             clock=self._steady)
        self._progress_timer = self.create_timer(self._progress_period, self._on_progress,
                                                 clock=self._steady)
        span = (self._end_ns - self._start_ns) * 1e-9
        log.info(f'replaying {path}: {len(self._outputs)} topics, {span:.3f} s of recorded '
                 f'time from offset {start_offset:g} s at rate {self._rate:g}'
                 + (', looped' if self._loop else ''))

    def _select(self, recording: Recording | SplitRecording, wanted: list[str],
                include_inputs: bool, publish_clock: bool) -> set[str]:
        """Return the topics to replay."""
        inputs: set[str] = set()
        meta = recording.metadata.get(METADATA_NAME, {})
        if 'input_topics' in meta and not include_inputs:
            try:
                inputs = set(json.loads(meta['input_topics']))
            except ValueError:
                self.get_logger().warning('unreadable input_topics metadata: replaying all')
        available = set(recording.topics)
        if wanted:
            unknown = sorted(set(wanted) - available)
            if unknown:
                raise ParameterError(f'topics {unknown} are not in the recording; it has '
                                     f'{sorted(available)}')
            chosen = set(wanted)
        else:
            chosen = available - inputs
        if publish_clock:
            chosen.discard('/clock')
        return {t for t in chosen if recording.topics[t].message_count or not recording.complete}

    # ------------------------------------------------------------------ playing

    def _begin_pass(self, delay: float = 0.0) -> None:
        self.passes += 1
        self._iter = self._recording.messages(set(self._outputs), self._start_ns,
                                              self._end_ns)
        self._next = next(self._iter, None)
        self._wall0 = self._clock_ns() + int(round(delay * 1e9))

    def _due(self, message: RecordedMessage) -> int:
        """Return when (clock_ns) a message is due: (log time - start) / rate after the start."""
        return self._wall0 + int((message.log_time_ns - self._start_ns) / self._rate)

    def _on_play(self) -> None:
        now = self._clock_ns()
        count = 0
        while self._next is not None and count < _BATCH:
            message = self._next
            if self._due(message) > now:
                break
            self._emit(message)
            count += 1
            self._next = next(self._iter, None)
        if self._next is None:
            if self._recording.problem != self._problem:
                self._problem = self._recording.problem
                self.get_logger().error(f'reading {self._recording.path} failed: '
                                        f'{self._problem}; replayed what came before')
            if self._loop and self.published:
                self._begin_pass()
            else:
                self._finish()
                return
        wait = self._due(self._next) - self._clock_ns()
        self._play_timer.timer_period_ns = max(wait, _MIN_PERIOD_NS)
        self._play_timer.reset()

    def _emit(self, message: RecordedMessage) -> None:
        if self._clock_pub is not None and message.log_time_ns != self._last_clock:
            self._last_clock = message.log_time_ns
            self._clock_pub.publish(ClockMessage(clock=_ns_time(message.log_time_ns)))
        self._outputs[message.topic].publish(bytes(message.data))
        self._position_ns = max(self._position_ns, message.log_time_ns)
        self.published += 1

    def _finish(self) -> None:
        self._play_timer.cancel()
        self._progress_timer.cancel()
        self._on_progress()
        wall = time.monotonic() - self._started
        self.get_logger().info(f'replay of {self._recording.path} finished: {self.published} '
                               f'messages in {wall:.2f} s')
        if not self.done.done():
            self.done.set_result(True)

    # ------------------------------------------------------------------ progress

    def progress(self) -> float:
        """Return the fraction of the selected time range replayed in this pass (0..1)."""
        span = self._end_ns - self._start_ns
        if span <= 0:
            return 1.0 if self._next is None else 0.0
        return min(max((self._position_ns - self._start_ns) / span, 0.0), 1.0)

    def _on_progress(self) -> None:
        fraction = self.progress()
        position = (self._position_ns - self._recording.start_ns) * 1e-9
        end = (self._end_ns - self._recording.start_ns) * 1e-9
        text = (f'{100.0 * fraction:.1f} % (t = {position:.3f} / {end:.3f} s after the first '
                f'message, {self.published} messages, pass {self.passes})')
        self.get_logger().info(f'replay {text}')
        incomplete = not self._recording.complete or bool(self._recording.problem)
        status = DiagnosticStatus(
            level=DiagnosticStatus.WARN if incomplete else DiagnosticStatus.OK,
            name=f'{self.get_fully_qualified_name()}: replay',
            message=(('replaying the readable part of a damaged file: ' if incomplete else
                      'replaying ') + text),
            hardware_id=str(self._recording.path),
            values=[KeyValue(key=k, value=v) for k, v in (
                ('progress', f'{fraction:.6f}'),
                ('position (s)', f'{position:.6f}'),
                ('end (s)', f'{end:.6f}'),
                ('messages published', str(self.published)),
                ('pass', str(self.passes)),
                ('rate', f'{self._rate:g}'),
                ('loop', str(self._loop)),
                ('finished', str(self._next is None and not self._loop)))])
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(array)


def main(args: list[str] | None = None) -> int:
    """Replay until the end (or until shut down); return the process exit status."""
    return run_node(ReplayNode, NODE_NAME, args, refusal='cannot replay',
                    spin=lambda node: rclpy.spin_until_future_complete(node, node.done))


if __name__ == '__main__':
    sys.exit(main())
