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
A node's topics as the recording sees them: registry, publishers, hooks, recorded inputs.

:class:`Outputs` takes the node (as rclpy's own helpers do, ``TimeSource(node=...)``) and
owns its publishers and raw subscriptions, made from the one topic table
(:data:`~cone_feeder_sim.formats.topics.TOPICS`: type and QoS). Messages are published as
CDR bytes from :mod:`~cone_feeder_sim.formats.cdr`; every published and received message
goes to the message hooks (:class:`~cone_feeder_sim.formats.topics.MessageRecord`, the exact
bytes), which is how the node's recording sees them. A received message larger than
:data:`MAX_RECORDED_INPUT_BYTES` is not passed on whole.
"""

from collections.abc import Callable, Mapping
from dataclasses import dataclass
import importlib
import time
from typing import Any

from rclpy.node import Node
from rclpy.subscription import Subscription

from .qos import rclpy_qos
from ..formats.cdr import CdrCodec
from ..formats.topics import MessageRecord, QosProfile, TOPICS, TopicSpec

__all__ = ['MAX_RECORDED_INPUT_BYTES', 'message_class', 'MessageHook', 'Output', 'Outputs',
           'TopicInfo']

#: Received messages larger than this (bytes) are not recorded whole (a million-pose spawn
#: is 56 MB); the inputs the engine applied from them are.
MAX_RECORDED_INPUT_BYTES = 4 * 1024 * 1024

MessageHook = Callable[[MessageRecord], None]


def message_class(type_name: str) -> Any:
    """Return the rclpy message class of ``pkg/msg/Type``."""
    package, kind, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


@dataclass(frozen=True)
class TopicInfo:
    """A topic of the node: resolved name, type, direction and QoS (for recorders)."""

    topic: str
    type_name: str
    direction: str
    qos: QosProfile


@dataclass(frozen=True)
class Output:
    """A publisher with its resolved topic, type name and CDR encoder."""

    publisher: Any
    topic: str
    type_name: str
    encode: Callable[[Any], bytes]


class Outputs:
    """The topics of ``node``: publishers and raw subscriptions, hooks, the topic registry."""

    def __init__(self, node: Node, codec: CdrCodec,
                 table: Mapping[str, TopicSpec] = TOPICS) -> None:
        """Start with no topic and no hook; topics are named in table (default sim_node's)."""
        self._node = node
        self._codec = codec
        self._table = table
        self._hooks: list[MessageHook] = []
        self._topics: dict[str, TopicInfo] = {}
        #: table name (``particles``, ``~/events``) -> resolved topic name
        self.names: dict[str, str] = {}

    def _register(self, name: str, topic: str, direction: str) -> None:
        spec = self._table[name]
        self._topics[topic] = TopicInfo(topic, spec.type_name, direction, spec.qos)
        self.names[name] = topic

    def publisher(self, name: str) -> Output:
        """Create the publisher of table topic ``name`` (its type and QoS from the table)."""
        spec = self._table[name]
        pub = self._node.create_publisher(message_class(spec.type_name), name,
                                          rclpy_qos(spec.qos))
        self._register(name, pub.topic_name, 'out')
        return Output(pub, pub.topic_name, spec.type_name, self._codec.encoder(spec.type_name))

    def subscription(self, name: str, callback: Callable[[bytes], None]) -> Subscription:
        """Create a raw (serialized bytes) subscription of table topic ``name``."""
        spec = self._table[name]
        sub = self._node.create_subscription(message_class(spec.type_name), name, callback,
                                             rclpy_qos(spec.qos), raw=True)
        self._register(name, sub.topic_name, 'in')
        return sub

    def topics(self) -> list[TopicInfo]:
        """Return the topics with types, directions and QoS, in the order they were made."""
        return list(self._topics.values())

    def input_topics(self) -> list[str]:
        """Return the resolved names of the received topics, sorted."""
        return sorted(info.topic for info in self._topics.values() if info.direction == 'in')

    def add_hook(self, hook: MessageHook) -> None:
        """Call hook with every published and received message (exact serialized bytes)."""
        self._hooks.append(hook)

    def remove_hook(self, hook: MessageHook) -> None:
        """Stop calling hook (nothing happens if it is not there)."""
        if hook in self._hooks:
            self._hooks.remove(hook)

    def publish(self, out: Output, message: dict[str, Any], stamp_ns: int) -> None:
        """Encode and publish a message (stamp: simulation time, ns) and pass it to the hooks."""
        data = out.encode(message)
        if self._node.context.ok():  # after a signal, the last ticks are still recorded
            out.publisher.publish(data)
        if self._hooks:
            self._emit(MessageRecord('out', out.topic, out.type_name, data, stamp_ns,
                                     time.time_ns()))

    def received(self, name: str, data: bytes, stamp_ns: int) -> bool:
        """
        Pass a message received on table topic ``name`` to the hooks.

        Returns False when it was too large to pass on whole (the caller says so in an
        event), True otherwise.
        """
        if not self._hooks:
            return True
        if len(data) > MAX_RECORDED_INPUT_BYTES:
            return False
        self._emit(MessageRecord('in', self.names[name], self._table[name].type_name,
                                 bytes(data), stamp_ns, time.time_ns()))
        return True

    def _emit(self, record: MessageRecord) -> None:
        for hook in list(self._hooks):
            try:
                hook(record)
            except Exception as exc:  # noqa: B902 - a broken hook must not stop the node
                self._node.get_logger().error(f'message hook {hook!r} failed: {exc}',
                                              throttle_duration_sec=5.0)
