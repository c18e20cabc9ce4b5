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
A Foxglove WebSocket client written for the tests on the published protocol.

RFC 6455 framing over a plain socket, the subprotocol ``foxglove.sdk.v1`` (what
foxglove-sdk's server speaks), the JSON ops ``serverInfo``, ``advertise`` and
``subscribe``, and binary Message Data (opcode 1: subscription id uint32, log time uint64
ns, payload). Protobuf payloads are decoded with the schema the server advertises (a
FileDescriptorSet), read with a small decoder of the protobuf wire format: no protobuf
package is needed.
"""

import base64
import json
import os
import socket
import struct
import threading
import time
from typing import Any

SUBPROTOCOL = 'foxglove.sdk.v1'


class FoxgloveClient:
    """A client that collects the messages of the topics it subscribes to, on a thread."""

    def __init__(self, port: int, host: str = '127.0.0.1', timeout: float = 30.0) -> None:
        """Connect, shake hands and start reading."""
        self.sock = socket.create_connection((host, port), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((
            f'GET / HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n'
            f'Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n'
            f'Sec-WebSocket-Protocol: {SUBPROTOCOL}\r\n\r\n').encode())
        self._buffer = b''
        while b'\r\n\r\n' not in self._buffer:
            self._buffer += self._recv()
        head, self._buffer = self._buffer.split(b'\r\n\r\n', 1)
        lines = head.decode().split('\r\n')
        if ' 101 ' not in lines[0]:
            raise ConnectionError(f'handshake refused: {lines[0]}')
        self.protocol = next((line.split(':', 1)[1].strip() for line in lines
                              if line.lower().startswith('sec-websocket-protocol:')), None)
        self.server_info: dict[str, Any] | None = None
        self.channels: dict[str, dict[str, Any]] = {}  # by topic
        self.messages: dict[str, list[tuple[int, bytes]]] = {}  # topic: [(log_time, payload)]
        self.arrivals: dict[str, list[float]] = {}  # topic: [monotonic time of arrival (s)]
        self._subscriptions: dict[int, str] = {}
        self._lock = threading.Lock()
        self.closed = False
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _recv(self) -> bytes:
        data = self.sock.recv(1 << 16)
        if not data:
            raise ConnectionError('server closed the connection')
        return data

    def _exact(self, count: int) -> bytes:
        while len(self._buffer) < count:
            self._buffer += self._recv()
        data, self._buffer = self._buffer[:count], self._buffer[count:]
        return data

    def _frame(self) -> tuple[int, bytes]:
        first, second = self._exact(2)
        length = second & 0x7F
        if length == 126:
            length = struct.unpack('>H', self._exact(2))[0]
        elif length == 127:
            length = struct.unpack('>Q', self._exact(8))[0]
        return first & 0x0F, self._exact(length)

    def _send(self, opcode: int, data: bytes) -> None:
        mask = os.urandom(4)
        size = len(data)
        if size < 126:
            head = bytes([0x80 | opcode, 0x80 | size])
        elif size < 1 << 16:
            head = bytes([0x80 | opcode, 0x80 | 126]) + struct.pack('>H', size)
        else:
            head = bytes([0x80 | opcode, 0x80 | 127]) + struct.pack('>Q', size)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(data))
        self.sock.sendall(head + mask + masked)

    def _read(self) -> None:
        try:
            while True:
                opcode, payload = self._frame()
                if opcode == 1:
                    self._on_json(json.loads(payload))
                elif opcode == 2 and payload[0] == 1:
                    subscription, log_time = struct.unpack_from('<IQ', payload, 1)
                    with self._lock:
                        topic = self._subscriptions.get(subscription)
                        if topic is not None:
                            self.messages.setdefault(topic, []).append(
                                (log_time, payload[13:]))
                            self.arrivals.setdefault(topic, []).append(time.monotonic())
                elif opcode == 9:
                    self._send(10, payload)  # pong
                elif opcode == 8:
                    break
        except (ConnectionError, OSError):
            pass
        self.closed = True

    def _on_json(self, message: dict[str, Any]) -> None:
        with self._lock:
            if message['op'] == 'serverInfo':
                self.server_info = message
            elif message['op'] == 'advertise':
                for channel in message['channels']:
                    self.channels[channel['topic']] = channel

    def wait_for(self, condition: Any, timeout: float = 60.0) -> None:
        """Wait until condition() holds (checked every 20 ms); fail after ``timeout`` s."""
        end = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > end:
                raise TimeoutError('the condition did not hold in time')
            if self.closed:
                raise ConnectionError('the connection closed')
            time.sleep(0.02)

    def subscribe(self, *topics: str) -> None:
        """Subscribe to the topics (waiting for their advertisement)."""
        self.wait_for(lambda: all(topic in self.channels for topic in topics))
        subscriptions = []
        with self._lock:
            for topic in topics:
                sub_id = len(self._subscriptions) + 1
                self._subscriptions[sub_id] = topic
                subscriptions.append({'id': sub_id, 'channelId': self.channels[topic]['id']})
        self._send(1, json.dumps({'op': 'subscribe', 'subscriptions': subscriptions}).encode())

    def received(self, topic: str) -> list[tuple[int, bytes]]:
        """Return a copy of the (log_time ns, payload) received on topic so far."""
        with self._lock:
            return list(self.messages.get(topic, ()))

    def json(self, topic: str) -> list[tuple[int, Any]]:
        """Return the (log_time, decoded JSON) of a JSON topic so far."""
        return [(t, json.loads(data)) for t, data in self.received(topic)]

    def decoded(self, topic: str) -> list[tuple[int, dict[str, Any]]]:
        """Return the (log_time, message as nested dicts) of a protobuf topic so far."""
        channel = self.channels[topic]
        schema = Schema(base64.b64decode(channel['schema']))
        return [(t, schema.decode(channel['schemaName'], data))
                for t, data in self.received(topic)]

    def close(self) -> None:
        """Close cleanly (a close frame, then the socket)."""
        try:
            self._send(8, struct.pack('>H', 1000))
        except OSError:
            pass
        self.sock.close()

    def vanish(self) -> None:
        """Drop the connection without a word, as a crashed client does."""
        self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()


# --------------------------------------------------------------------------- protobuf wire


def _varint(data: bytes, pos: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, pos


def wire_fields(data: bytes) -> list[tuple[int, int, Any]]:
    """Return the (field number, wire type, raw value) of a protobuf message, in order."""
    fields = []
    pos = 0
    while pos < len(data):
        key, pos = _varint(data, pos)
        number, wire = key >> 3, key & 7
        if wire == 0:
            value, pos = _varint(data, pos)
        elif wire == 1:
            value, pos = data[pos:pos + 8], pos + 8
        elif wire == 2:
            size, pos = _varint(data, pos)
            value, pos = data[pos:pos + size], pos + size
        elif wire == 5:
            value, pos = data[pos:pos + 4], pos + 4
        else:
            raise ValueError(f'wire type {wire} is not supported')
        fields.append((number, wire, value))
    return fields


#: FieldDescriptorProto types (descriptor.proto) the decoder reads.
_DOUBLE, _FLOAT, _INT64, _UINT64, _INT32, _BOOL, _STRING, _MESSAGE, _UINT32, _ENUM = (
    1, 2, 3, 4, 5, 8, 9, 11, 13, 14)
_FIXED32 = 7


class Schema:
    """The messages of a FileDescriptorSet: field names, numbers, types, repetition."""

    def __init__(self, descriptor_set: bytes) -> None:
        """Read the FileDescriptorSet (descriptor.proto field numbers)."""
        self.messages: dict[str, dict[int, tuple[str, int, str, bool]]] = {}
        for number, _, file_bytes in wire_fields(descriptor_set):
            if number != 1:
                continue
            file_fields = wire_fields(file_bytes)
            package = next((v.decode() for n, _, v in file_fields if n == 2), '')
            for n, _, message_bytes in file_fields:
                if n == 4:
                    self._message(package, message_bytes)

    def _message(self, package: str, data: bytes) -> None:
        parts = wire_fields(data)
        name = next(v.decode() for n, _, v in parts if n == 1)
        fields = {}
        for n, _, field_bytes in parts:
            if n != 2:
                continue
            f = {k: v for k, _, v in wire_fields(field_bytes)}
            type_name = f.get(6, b'').decode().lstrip('.')
            fields[f[3]] = (f[1].decode(), f[5], type_name, f.get(4) == 3)  # LABEL_REPEATED
        self.messages[f'{package}.{name}'] = fields

    def decode(self, name: str, data: bytes) -> dict[str, Any]:
        """Return the message ``name`` in data as a dict (repeated fields as lists)."""
        fields = self.messages[name]
        out: dict[str, Any] = {}
        for number, wire, raw in wire_fields(data):
            if number not in fields:
                continue
            field_name, kind, type_name, repeated = fields[number]
            if kind == _MESSAGE:
                values = [self.decode(type_name, raw)]
            elif kind == _DOUBLE and wire == 2:
                values = list(struct.unpack(f'<{len(raw) // 8}d', raw))
            elif kind == _DOUBLE:
                values = [struct.unpack('<d', raw)[0]]
            elif kind == _FLOAT:
                values = [struct.unpack('<f', raw)[0]]
            elif kind == _STRING:
                values = [raw.decode()]
            elif kind == _FIXED32:
                values = [struct.unpack('<I', raw)[0]]
            else:
                values = [raw]
            if repeated:
                out.setdefault(field_name, []).extend(values)
            else:
                out[field_name] = values[0]
        return out
