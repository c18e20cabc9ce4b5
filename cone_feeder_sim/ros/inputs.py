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
The live node's inputs, from serialized bytes to engine input: what is taken, what refused.

:class:`Inputs` decodes a received message (rotation_cmd, spawn, channel_feed), screens what
the engine does not know about (the frame of spawn poses), and hands the rest to the
engine, which owns every rule on its inputs (:meth:`FeederEngine.command` says what it
clamped, :meth:`FeederEngine.offer_spawn` what it refused). The outcome lists the refusals
(the node counts, logs and records them) and a warning to log. :class:`RefusalThrottle`
keeps the log at one line a second per kind of refusal. Free of rclpy.
"""

from collections.abc import Callable
from dataclasses import dataclass
import math
import time

import numpy as np

from ..errors import ConeFeederError
from ..feeder.engine import ChannelFeed, FeederEngine, Refusal
from ..formats.cdr import CdrCodec, CdrError
from ..formats.messages import pose_array_positions
from ..formats.topics import TOPICS

__all__ = ['InputOutcome', 'Inputs', 'RefusalThrottle']


@dataclass(frozen=True)
class InputOutcome:
    """
    What became of one received message: refusals, and a warning to log (or None).

    entries: each refusal with its log line (None: ``<kind> refused: <reason>``).
    """

    entries: tuple[tuple[Refusal, str | None], ...] = ()
    warning: str | None = None

    @classmethod
    def refused(cls, *refusals: Refusal) -> 'InputOutcome':
        """Return the outcome of refusals logged the usual way."""
        return cls(tuple((refusal, None) for refusal in refusals))

    @property
    def refusals(self) -> tuple[Refusal, ...]:
        """Return the refusals."""
        return tuple(refusal for refusal, _ in self.entries)

    def lines(self) -> list[tuple[Refusal, str]]:
        """Return each refusal with its log line."""
        return [(r, text or f'{r.kind} refused: {r.reason}') for r, text in self.entries]


class Inputs:
    """Turns received messages into engine input (see the module documentation)."""

    def __init__(self, engine: FeederEngine, codec: CdrCodec, frame_id: str) -> None:
        """Take input for ``engine``; spawn poses in ``frame_id`` (or an empty frame)."""
        self._engine = engine
        self._codec = codec
        self._frame = frame_id
        self._handlers: dict[str, Callable[[bytes], InputOutcome]] = {
            'rotation_cmd': self._rotation_cmd, 'spawn': self._spawn,
            'channel_feed': self._channel_feed}

    def handle(self, name: str, data: bytes) -> InputOutcome:
        """Take a message received on input topic ``name`` (rotation_cmd, spawn, channel_feed)."""
        return self._handlers[name](data)

    def _decode(self, name: str, data: bytes) -> dict:
        return self._codec.decode(TOPICS[name].type_name, data, strict=False)

    def _rotation_cmd(self, data: bytes) -> InputOutcome:
        try:
            value = self._decode('rotation_cmd', data)['data']
            target = self._engine.command(value)
        except (CdrError, ConeFeederError) as exc:
            return InputOutcome.refused(Refusal('rotation_cmd', 1, str(exc)))
        if target != value:
            return InputOutcome(warning=f'rotation_cmd {value:g} rad/s clamped to the limit '
                                        f'{abs(target):g} rad/s')
        return InputOutcome()

    def _channel_feed(self, data: bytes) -> InputOutcome:
        try:
            values = self._decode('channel_feed', data)['data']
            self._engine.submit(ChannelFeed(tuple(values)))
        except (CdrError, ConeFeederError) as exc:
            return InputOutcome.refused(Refusal('channel_feed', 1, str(exc)))
        return InputOutcome()

    def _spawn(self, data: bytes) -> InputOutcome:
        try:
            frame, positions = pose_array_positions(data)
        except CdrError as exc:
            return InputOutcome.refused(Refusal('spawn', 1, f'cannot decode the message: {exc}'))
        if frame not in ('', self._frame):
            return InputOutcome.refused(Refusal(
                'spawn', positions.shape[0], f'poses are in frame {frame!r}, expected '
                f'{self._frame!r} (or an empty frame_id)'))
        # new pieces start at rest in the world frame (dropped)
        offer = self._engine.offer_spawn(positions, np.zeros_like(positions))
        entries: list[tuple[Refusal, str | None]] = []
        for refusal in offer.refusals:
            if refusal is offer.invalid:  # said in the node's words: poses
                reason = refusal.reason.replace('position[', 'pose [')
                entries.append((Refusal('spawn', refusal.count, reason),
                                f'spawn: refused {refusal.count} of {offer.total} poses: '
                                f'{reason}'))
            else:
                entries.append((refusal, None))
        return InputOutcome(tuple(entries))


class RefusalThrottle:
    """Tells when to log a refusal: at most once per ``interval`` s for each kind of it."""

    def __init__(self, interval: float = 1.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        """Log the first refusal of every kind."""
        self._interval = interval
        self._clock = clock
        self._last: dict[tuple[str, str], float] = {}

    def due(self, what: str, reason: str) -> bool:
        """Tell whether to log this refusal of ``what`` (kinds: what, the reason's start)."""
        # rclpy throttles per call site, not per kind of refusal
        key = (what, reason.split(':')[0][:40])
        now = self._clock()
        if now - self._last.get(key, -math.inf) >= self._interval:
            self._last[key] = now
            return True
        return False
