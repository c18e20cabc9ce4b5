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
Exact ROS 2 CDR (plain XCDR1, little endian) encoder and decoder.

The wire format is the one rmw_fastrtps produces: a 4-byte encapsulation
header ``00 01 00 00``, then the fields in order, each primitive aligned to
its own size counted from the end of the header; strings are a ``uint32``
length that counts the terminating NUL, the UTF-8 bytes and the NUL;
sequences are a ``uint32`` element count followed by the elements (no
alignment padding when the sequence is empty); fixed arrays have no count;
``bool`` is one byte and a message without fields is one ``uint8``. The
encoder writes nothing past the last field.

Messages to encode may be mappings (``msg[name]``) or objects with attributes
(e.g. rclpy messages), nested freely. Fast paths: ``uint8[]``/``byte[]``
fields take ``bytes``, ``bytearray``, ``memoryview``, ``array.array`` or any
numpy array (a structured array is written as its raw memory); other numeric
sequences take numpy arrays (or lists); a sequence of a message type whose
leaves are all the same fixed-size primitive (``geometry_msgs/msg/Pose``,
``Point``, ``ColorRGBA``...) takes an ``(n, n_leaves)`` numpy array or a
structured array with that many leaves and is written in one go.

Per-type encoders and decoders are generated once as Python code (with
alignment precomputed for each of the 8 possible start offsets of a run of
fixed-size fields) and cached by type name. :func:`decode` returns nested
dicts: ``uint8``/``byte`` arrays as ``bytes``, other numeric arrays as numpy
arrays, strings as ``str``, arrays of strings or messages as lists.
"""

import array
import collections.abc
import keyword
import struct
import threading
from typing import Any

import numpy as np
from numpy.lib import recfunctions

from .msgtypes import (
    ArrayKind, default_registry, FieldSpec, MessageDefinitionError, MessageRegistry, MessageSpec,
    normalize_type_name)
from ..errors import ConeFeederError

__all__ = [
    'ENCAPSULATION_HEADER',
    'CdrCodec',
    'CdrError',
    'decode',
    'default_codec',
    'default_message',
    'encode',
]

#: Encapsulation header of plain CDR, little endian (CDR_LE, no options).
ENCAPSULATION_HEADER = b'\x00\x01\x00\x00'

Buffer = bytes | bytearray | memoryview
StructEncoder = collections.abc.Callable[[bytearray, Any], None]
StructDecoder = collections.abc.Callable[[bytes, int], tuple[dict[str, Any], int]]


class CdrError(ConeFeederError, ValueError):
    """A message cannot be encoded to or decoded from CDR."""


class _Prim:
    """Wire properties of one primitive type."""

    __slots__ = ('as_bytes', 'code', 'dtype', 'name', 'size')

    def __init__(self, name: str, code: str, dtype: str) -> None:
        self.name = name
        self.code = code
        self.size = struct.calcsize('<' + code)
        self.dtype = np.dtype(dtype)
        self.as_bytes = name in ('uint8', 'byte')


_PRIMS: dict[str, _Prim] = {
    name: _Prim(name, code, dtype) for name, code, dtype in (
        ('bool', '?', '?'),
        ('byte', 'B', 'u1'),
        ('char', 'B', 'u1'),
        ('int8', 'b', 'i1'),
        ('uint8', 'B', 'u1'),
        ('int16', 'h', '<i2'),
        ('uint16', 'H', '<u2'),
        ('int32', 'i', '<i4'),
        ('uint32', 'I', '<u4'),
        ('int64', 'q', '<i8'),
        ('uint64', 'Q', '<u8'),
        ('float32', 'f', '<f4'),
        ('float64', 'd', '<f8'),
    )
}

_U32 = struct.Struct('<I')
_ZEROS = tuple(bytes(n) for n in range(8))
#: ``pack(n)`` writing the alignment padding and a uint32 (string length or
#: element count), indexed by ``len(buffer) % 4``.
_ALIGNED_U32 = tuple(struct.Struct(f'<{pad}xI').pack for pad in (0, 3, 2, 1))


# ---------------------------------------------------------------------------
# Encoding helpers (called from generated code).
# ---------------------------------------------------------------------------

def _byte(value: Any) -> int:
    """Return a ``byte``/``char`` value given as int, 1-byte bytes or 1-char str."""
    if isinstance(value, (bytes, bytearray)):
        if len(value) != 1:
            raise CdrError(f'a byte value must have length 1, got {len(value)}')
        return value[0]
    if isinstance(value, str):
        if len(value) != 1:
            raise CdrError(f'a char value must have length 1, got {len(value)}')
        return ord(value)
    return value


def _fixed(value: Any, size: int, prim: _Prim) -> Any:
    """Return the values of a fixed primitive array as something to unpack into struct."""
    if isinstance(value, np.ndarray):
        value = value.ravel().tolist()
    elif (prim.as_bytes or prim.name == 'char') and isinstance(value, (list, tuple)) and (
            value and isinstance(value[0], (bytes, str))):
        value = [_byte(item) for item in value]
    if len(value) != size:
        raise CdrError(f'fixed array needs exactly {size} values, got {len(value)}')
    return value


def _check_bound(count: int, bound: int | None, what: str) -> None:
    if bound is not None and count > bound:
        raise CdrError(f'{what} has {count} elements, more than its bound {bound}')


def _string_bytes(value: Any, bound: int | None) -> bytes:
    if type(value) is str:
        data = value.encode('utf-8')
    elif isinstance(value, (bytes, bytearray, memoryview)):
        data = bytes(value)
    else:
        raise CdrError(f'a string field needs str, got {type(value).__name__}')
    if bound is not None and len(data) > bound:
        raise CdrError(f'string of {len(data)} bytes exceeds its bound {bound}')
    return data


def _write_string(buf: bytearray, value: Any, bound: int | None = None) -> None:
    data = _string_bytes(value, bound)
    buf += _ALIGNED_U32[len(buf) & 3](len(data) + 1)
    buf += data
    buf.append(0)


def _write_string_array(
    buf: bytearray, value: Any, size: int | None, bound: int | None,
    sbound: int | None
) -> None:
    count = len(value)
    if size is not None:
        if count != size:
            raise CdrError(f'fixed array needs exactly {size} strings, got {count}')
    else:
        _check_bound(count, bound, 'string sequence')
        buf += _ALIGNED_U32[len(buf) & 3](count)
    for item in value:
        _write_string(buf, item, sbound)


def _cast_array(value: np.ndarray, prim: _Prim) -> np.ndarray:
    """Convert a numpy array to the wire dtype of ``prim`` without silent value changes."""
    target = prim.dtype
    source = value.dtype
    if source == target:
        return value
    if target.kind == 'b':
        if source.kind not in 'biu':
            raise CdrError(f'cannot write a {source} array as bool values')
        return value.astype(target)
    if target.kind in 'iu':
        if source.kind == 'b':
            return value.astype(target)
        if source.kind not in 'iu':
            hint = ' (write raw memory with array.view(numpy.uint8))' if prim.size == 1 else ''
            raise CdrError(f'cannot write a {source} array as {prim.name} values{hint}')
        if value.size:
            info = np.iinfo(target)
            if value.min() < info.min or value.max() > info.max:
                raise CdrError(f'values out of range for {prim.name}')
        return value.astype(target)
    if source.kind not in 'biuf':
        raise CdrError(f'cannot write a {source} array as {prim.name} values')
    return value.astype(target)


def _prim_payload(value: Any, prim: _Prim) -> tuple[int, Buffer]:
    """Return the element count and little-endian payload of a primitive array."""
    if isinstance(value, np.ndarray):
        if prim.size == 1 and value.dtype.kind == 'V':
            data = value.tobytes()
            return len(data), data
        value = _cast_array(value, prim)
        return value.size, value.tobytes()
    if prim.size == 1 and isinstance(value, (bytes, bytearray)):
        return len(value), value
    if isinstance(value, (memoryview, array.array)):
        view = memoryview(value)
        if prim.size == 1 and view.itemsize == 1 and view.format in ('B', 'b', 'c'):
            view = view.cast('B') if view.format != 'B' else view
            return view.nbytes, view
        return _prim_payload(np.asarray(view), prim)
    count = len(value)
    if not count:
        return 0, b''
    if prim.as_bytes or prim.name == 'char':
        if isinstance(value[0], (bytes, bytearray)):
            data = b''.join(value)
            if len(data) != count:
                raise CdrError('byte sequence elements must each be one byte long')
            return count, data
        if isinstance(value[0], str):
            value = [_byte(item) for item in value]
    return count, struct.pack(f'<{count}{prim.code}', *value)


def _write_prim_array(
    buf: bytearray, value: Any, prim: _Prim, size: int | None, bound: int | None
) -> None:
    count, data = _prim_payload(value, prim)
    if size is not None:
        if count != size:
            raise CdrError(f'fixed array needs exactly {size} values, got {count}')
    else:
        _check_bound(count, bound, f'{prim.name} sequence')
        buf += _ALIGNED_U32[len(buf) & 3](count)
    if count:
        buf += _ZEROS[(4 - len(buf)) % prim.size]
        buf += data


class _Block:
    """Fast path for arrays of a message whose leaves all share one primitive type."""

    __slots__ = ('leaves', 'prim', 'type_name')

    def __init__(self, prim: _Prim, leaves: int, type_name: str) -> None:
        self.prim = prim
        self.leaves = leaves
        self.type_name = type_name

    def payload(self, value: np.ndarray) -> tuple[int, bytes]:
        if value.dtype.names is not None:
            if value.ndim != 1:
                raise CdrError(f'a structured array of {self.type_name} must be 1-D')
            value = recfunctions.structured_to_unstructured(value)
        if value.ndim == 1 and self.leaves == 1:
            value = value.reshape(-1, 1)
        if value.ndim != 2 or value.shape[1] != self.leaves:
            raise CdrError(
                f'an array of {self.type_name} needs shape (n, {self.leaves}), '
                f'got {value.shape}')
        data = _cast_array(np.ascontiguousarray(value), self.prim)
        return value.shape[0], data.tobytes()


def _write_struct_array(
    buf: bytearray, value: Any, encoder: StructEncoder, block: _Block | None,
    size: int | None, bound: int | None, type_name: str
) -> None:
    if isinstance(value, np.ndarray):
        if block is None:
            raise CdrError(
                f'{type_name} has fields of different or variable-size types; '
                'pass a list of mappings or objects, not a numpy array')
        count, data = block.payload(value)
    else:
        count, data = len(value), None
    if size is not None:
        if count != size:
            raise CdrError(f'fixed array needs exactly {size} {type_name}, got {count}')
    else:
        _check_bound(count, bound, f'{type_name} sequence')
        buf += _ALIGNED_U32[len(buf) & 3](count)
    if data is not None:
        if count:
            buf += _ZEROS[(4 - len(buf)) % block.prim.size]
            buf += data
        return
    for item in value:
        encoder(buf, item)


# ---------------------------------------------------------------------------
# Decoding helpers (called from generated code).
# ---------------------------------------------------------------------------

def _read_count(data: bytes, pos: int) -> tuple[int, int]:
    pos += -pos & 3
    (count,) = _U32.unpack_from(data, pos)
    return count, pos + 4


def _read_string(data: bytes, pos: int) -> tuple[str, int]:
    length, pos = _read_count(data, pos)
    if not length:
        return '', pos
    end = pos + length
    if end > len(data):
        raise CdrError(f'string of {length} bytes at offset {pos - 4} runs past the end')
    if data[end - 1]:
        raise CdrError(f'string at offset {pos - 4} is not NUL-terminated')
    return data[pos:end - 1].decode('utf-8'), end


def _read_string_array(
    data: bytes, pos: int, size: int | None
) -> tuple[list[str], int]:
    if size is None:
        size, pos = _read_count(data, pos)
        if size > len(data) - pos:
            raise CdrError(f'string sequence of {size} elements runs past the end')
    result = []
    for _ in range(size):
        item, pos = _read_string(data, pos)
        result.append(item)
    return result, pos


def _read_prim_array(
    data: bytes, pos: int, prim: _Prim, size: int | None
) -> tuple[bytes | np.ndarray, int]:
    if size is None:
        size, pos = _read_count(data, pos)
    if size:
        pos += (4 - pos) % prim.size
    end = pos + size * prim.size
    if end > len(data):
        raise CdrError(f'{prim.name} array of {size} elements runs past the end')
    if prim.as_bytes:
        return data[pos:end], end
    return np.frombuffer(data, prim.dtype, size, pos).copy(), end


def _read_struct_array(
    data: bytes, pos: int, decoder: StructDecoder, size: int | None
) -> tuple[list[dict[str, Any]], int]:
    if size is None:
        size, pos = _read_count(data, pos)
        if size > len(data) - pos:
            raise CdrError(f'message sequence of {size} elements runs past the end')
    result = []
    for _ in range(size):
        item, pos = decoder(data, pos)
        result.append(item)
    return result, pos


def _fixed_values(values: tuple[Any, ...], prim: _Prim) -> bytes | np.ndarray:
    if prim.as_bytes:
        return bytes(values)
    return np.array(values, dtype=prim.dtype)


# ---------------------------------------------------------------------------
# Code generation.
# ---------------------------------------------------------------------------

class _RunItem:
    """A fixed-size primitive (or fixed primitive array) inside a run."""

    __slots__ = ('count', 'expr', 'prim')

    def __init__(self, prim: _Prim, count: int, expr: str) -> None:
        self.prim = prim
        self.count = count
        self.expr = expr


def _run_structs(items: list[_RunItem]) -> tuple[struct.Struct, ...]:
    """Return one Struct per ``len(buffer) % 8`` with the alignment padding baked in."""
    structs = []
    for residue in range(8):
        offset = (residue - 4) % 8
        fmt = ['<']
        for item in items:
            pad = -offset % item.prim.size
            if pad:
                fmt.append(f'{pad}x')
            fmt.append(f'{item.count}{item.prim.code}')
            offset += pad + item.count * item.prim.size
        structs.append(struct.Struct(''.join(fmt)))
    return tuple(structs)


class _Generator:
    """Common state of the encoder and decoder code generators."""

    def __init__(self, codec: 'CdrCodec', spec: MessageSpec) -> None:
        self.codec = codec
        self.spec = spec
        self.lines: list[str] = []
        self.namespace: dict[str, Any] = {}
        self.run: list[_RunItem] = []
        self.counter = 0

    def name(self, prefix: str) -> str:
        self.counter += 1
        return f'_{prefix}{self.counter}'

    def constant(self, prefix: str, value: Any) -> str:
        name = self.name(prefix)
        self.namespace[name] = value
        return name

    def prim(self, field: FieldSpec) -> _Prim | None:
        """Return the wire properties of a primitive field's type, None for string or message."""
        prim = _PRIMS.get(field.base_type)
        if prim is None and field.is_primitive and field.base_type != 'string':
            raise CdrError(
                f'{self.spec.type_name}.{field.name}: {field.base_type} fields are not supported')
        return prim

    def build_function(self, header: str, footer: list[str], entry: str) -> Any:
        source = '\n'.join([header] + ['    ' + line for line in self.lines + footer])
        namespace = dict(self.namespace)
        try:
            exec(compile(source, f'<cdr {self.spec.type_name}>', 'exec'), namespace)  # noqa: S102
        except SyntaxError as err:  # pragma: no cover - would be a generator bug
            raise CdrError(f'internal error generating code for {self.spec.type_name}') from err
        function = namespace[entry]
        function.__source__ = source
        return function


class _EncoderGenerator(_Generator):
    """Generate ``encode(buf, value)`` for one message type."""

    def build(self) -> StructEncoder:
        self.namespace.update(
            _Mapping=collections.abc.Mapping, _byte=_byte, _fixed=_fixed,
            _string_bytes=_string_bytes,
            _aligned_u32=_ALIGNED_U32,
            _write_string_array=_write_string_array, _write_prim_array=_write_prim_array,
            _write_struct_array=_write_struct_array)
        self.emit_struct(self.spec, 'value')
        self.flush_run()
        return self.build_function('def encode(buf, value):', ['return None'], 'encode')

    def flush_run(self) -> None:
        if not self.run:
            return
        structs = self.constant('run', _run_structs(self.run))
        args = ', '.join(item.expr for item in self.run)
        self.lines.append(f'buf += {structs}[len(buf) & 7].pack({args})')
        self.run = []

    def emit_string(self, variable: str, bound: int | None) -> None:
        data = self.name('b')
        if bound is None:
            self.lines.append(
                f"{data} = {variable}.encode('utf-8') if type({variable}) is str "
                f'else _string_bytes({variable}, None)')
        else:
            self.lines.append(f'{data} = _string_bytes({variable}, {bound!r})')
        self.lines.append(f'buf += _aligned_u32[len(buf) & 3](len({data}) + 1)')
        self.lines.append(f'buf += {data}')
        self.lines.append('buf.append(0)')

    def emit_struct(self, spec: MessageSpec, source: str) -> None:
        if not spec.fields:
            self.run.append(_RunItem(_PRIMS['uint8'], 1, '0'))
            return
        variables = [self.name('v') for _ in spec.fields]
        targets = ', '.join(variables) + ','
        by_key = ', '.join(f'{source}[{field.name!r}]' for field in spec.fields)
        by_attr = ', '.join(
            f'getattr({source}, {field.name!r})' if keyword.iskeyword(field.name)
            else f'{source}.{field.name}' for field in spec.fields)
        self.lines.append(f'if type({source}) is dict or isinstance({source}, _Mapping):')
        self.lines.append(f'    {targets} = {by_key},')
        self.lines.append('else:')
        self.lines.append(f'    {targets} = {by_attr},')
        for field, variable in zip(spec.fields, variables):
            self.emit_field(field, variable)

    def emit_field(self, field: FieldSpec, variable: str) -> None:
        base = field.base_type
        prim = self.prim(field)
        fixed = field.array_size if field.array_kind is ArrayKind.FIXED else None
        bound = field.array_size if field.array_kind is ArrayKind.BOUNDED else None
        if not field.is_array:
            if prim is not None:
                expr = f'_byte({variable})' if base in ('byte', 'char') else variable
                self.run.append(_RunItem(prim, 1, expr))
            elif base == 'string':
                self.flush_run()
                self.emit_string(variable, field.string_bound)
            else:
                self.emit_struct(self.codec.spec(base), variable)
            return
        if prim is not None and fixed is not None:
            prim_name = self.constant('p', prim)
            self.run.append(_RunItem(prim, fixed, f'*_fixed({variable}, {fixed}, {prim_name})'))
            return
        self.flush_run()
        if prim is not None:
            prim_name = self.constant('p', prim)
            call = f'_write_prim_array(buf, {variable}, {prim_name}, {fixed!r}, {bound!r})'
        elif base == 'string':
            call = (
                f'_write_string_array(buf, {variable}, {fixed!r}, {bound!r}, '
                f'{field.string_bound!r})')
        else:
            encoder = self.constant('enc', self.codec.struct_encoder(base))
            block = self.constant('blk', self.codec.block(base))
            call = (
                f'_write_struct_array(buf, {variable}, {encoder}, {block}, {fixed!r}, '
                f'{bound!r}, {base!r})')
        if fixed is None:
            # Empty sequences are common (Marker has six): skip the call for them.
            self.lines.append(f'if len({variable}) == 0:')
            self.lines.append('    buf += _aligned_u32[len(buf) & 3](0)')
            self.lines.append('else:')
            self.lines.append(f'    {call}')
        else:
            self.lines.append(call)


class _DecoderGenerator(_Generator):
    """Generate ``decode(data, pos) -> (dict, pos)`` for one message type."""

    def build(self) -> StructDecoder:
        self.namespace.update(
            _read_string=_read_string, _read_string_array=_read_string_array,
            _read_prim_array=_read_prim_array, _read_struct_array=_read_struct_array,
            _fixed_values=_fixed_values)
        self.pending: list[tuple[str, _RunItem]] = []
        expr = self.emit_struct(self.spec)
        self.flush_run()
        return self.build_function('def decode(data, pos):', [f'return {expr}, pos'], 'decode')

    def flush_run(self) -> None:
        if not self.pending:
            return
        items = [item for _, item in self.pending]
        structs = self.constant('run', _run_structs(items))
        layout = self.name('s')
        values = self.name('t')
        self.lines.append(f'{layout} = {structs}[pos & 7]')
        self.lines.append(f'{values} = {layout}.unpack_from(data, pos)')
        self.lines.append(f'pos += {layout}.size')
        index = 0
        for placeholder, item in self.pending:
            if item.count == 1 and item.expr == 'scalar':
                value = f'{values}[{index}]'
            else:
                prim_name = self.constant('p', item.prim)
                value = f'_fixed_values({values}[{index}:{index + item.count}], {prim_name})'
            self.lines.append(f'{placeholder} = {value}')
            index += item.count
        self.pending = []

    def emit_struct(self, spec: MessageSpec) -> str:
        if not spec.fields:
            placeholder = self.name('d')
            self.pending.append((placeholder, _RunItem(_PRIMS['uint8'], 1, 'scalar')))
            return '{}'
        parts = []
        for field in spec.fields:
            parts.append(f'{field.name!r}: {self.emit_field(field)}')
        return '{' + ', '.join(parts) + '}'

    def emit_field(self, field: FieldSpec) -> str:
        base = field.base_type
        prim = self.prim(field)
        fixed = field.array_size if field.array_kind is ArrayKind.FIXED else None
        if not field.is_array:
            if prim is not None:
                placeholder = self.name('d')
                self.pending.append((placeholder, _RunItem(prim, 1, 'scalar')))
                return placeholder
            if base != 'string':
                return self.emit_struct(self.codec.spec(base))
            self.flush_run()
            placeholder = self.name('d')
            self.lines.append(f'{placeholder}, pos = _read_string(data, pos)')
            return placeholder
        if prim is not None and fixed is not None:
            placeholder = self.name('d')
            self.pending.append((placeholder, _RunItem(prim, fixed, 'array')))
            return placeholder
        self.flush_run()
        placeholder = self.name('d')
        if prim is not None:
            prim_name = self.constant('p', prim)
            self.lines.append(
                f'{placeholder}, pos = _read_prim_array(data, pos, {prim_name}, {fixed!r})')
        elif base == 'string':
            self.lines.append(f'{placeholder}, pos = _read_string_array(data, pos, {fixed!r})')
        else:
            decoder = self.constant('dec', self.codec.struct_decoder(base))
            self.lines.append(
                f'{placeholder}, pos = _read_struct_array(data, pos, {decoder}, {fixed!r})')
        return placeholder


# ---------------------------------------------------------------------------
# Public codec.
# ---------------------------------------------------------------------------

class CdrCodec:
    """CDR encoder/decoder over a :class:`MessageRegistry`, with per-type caches."""

    def __init__(self, registry: MessageRegistry | None = None) -> None:
        """Use ``registry`` for definitions (default: rosbags' ROS 2 Jazzy types)."""
        self.registry = registry if registry is not None else default_registry()
        self._lock = threading.RLock()
        self._struct_encoders: dict[str, StructEncoder] = {}
        self._struct_decoders: dict[str, StructDecoder] = {}
        self._blocks: dict[str, _Block | None] = {}
        self._encoders: dict[str, collections.abc.Callable[[Any], bytes]] = {}

    def spec(self, type_name: str) -> MessageSpec:
        """Return the definition of ``type_name``, as :class:`CdrError` if missing."""
        try:
            return self.registry.spec(type_name)
        except MessageDefinitionError as err:
            raise CdrError(str(err)) from err

    def struct_encoder(self, type_name: str) -> StructEncoder:
        """Return the cached ``encode(buf, value)`` that appends one message body."""
        canonical = normalize_type_name(type_name)
        encoder = self._struct_encoders.get(canonical)
        if encoder is None:
            with self._lock:
                encoder = self._struct_encoders.get(canonical)
                if encoder is None:
                    encoder = _EncoderGenerator(self, self.spec(canonical)).build()
                    self._struct_encoders[canonical] = encoder
        return encoder

    def struct_decoder(self, type_name: str) -> StructDecoder:
        """Return the cached ``decode(data, pos) -> (dict, pos)`` of one message body."""
        canonical = normalize_type_name(type_name)
        decoder = self._struct_decoders.get(canonical)
        if decoder is None:
            with self._lock:
                decoder = self._struct_decoders.get(canonical)
                if decoder is None:
                    decoder = _DecoderGenerator(self, self.spec(canonical)).build()
                    self._struct_decoders[canonical] = decoder
        return decoder

    def _leaf_prims(self, spec: MessageSpec) -> list[tuple[_Prim, int]] | None:
        leaves: list[tuple[_Prim, int]] = []
        for field in spec.fields:
            if field.array_kind not in (ArrayKind.NONE, ArrayKind.FIXED):
                return None
            count = field.array_size if field.array_kind is ArrayKind.FIXED else 1
            prim = _PRIMS.get(field.base_type)
            if prim is not None:
                leaves.append((prim, count or 1))
            elif field.is_primitive:
                return None
            else:
                nested = self._leaf_prims(self.spec(field.base_type))
                if nested is None:
                    return None
                leaves.extend(nested * (count or 1))
        return leaves

    def block(self, type_name: str) -> _Block | None:
        """Return the numpy fast path of arrays of ``type_name``, or None if it has none."""
        canonical = normalize_type_name(type_name)
        if canonical not in self._blocks:
            leaves = self._leaf_prims(self.spec(canonical))
            block = None
            if leaves and len({prim.name for prim, _ in leaves}) == 1:
                block = _Block(leaves[0][0], sum(count for _, count in leaves), canonical)
            self._blocks[canonical] = block
        return self._blocks[canonical]

    def encoder(self, type_name: str) -> collections.abc.Callable[[Any], bytes]:
        """Return a cached function ``message -> CDR bytes`` for ``type_name``."""
        canonical = normalize_type_name(type_name)
        function = self._encoders.get(canonical)
        if function is not None:
            return function
        body = self.struct_encoder(canonical)
        header = ENCAPSULATION_HEADER

        def encode_message(message: Any) -> bytes:
            buf = bytearray(header)
            try:
                body(buf, message)
            except CdrError as err:
                raise CdrError(f'cannot encode {canonical}: {err}') from None
            except (struct.error, TypeError, KeyError, AttributeError, ValueError,
                    OverflowError, IndexError) as err:
                raise CdrError(
                    f'cannot encode {canonical}: {type(err).__name__}: {err}') from err
            return bytes(buf)

        self._encoders[canonical] = encode_message
        return encode_message

    def encode(self, type_name: str, message: Any) -> bytes:
        """Return the exact CDR bytes (with encapsulation header) of ``message``."""
        return self.encoder(type_name)(message)

    def decode(self, type_name: str, data: Buffer, *, strict: bool = True) -> dict[str, Any]:
        """
        Decode CDR ``data`` of ``type_name`` into nested dicts.

        With ``strict`` the header must be exactly ``00 01 00 00`` and no byte
        may follow the last field; otherwise the options bytes and trailing
        bytes (e.g. the padding rmw appends) are ignored.
        """
        decoder = self.struct_decoder(type_name)
        payload = bytes(data)
        if len(payload) < 4 or payload[0] != 0 or payload[1] != 1:
            raise CdrError(
                f'cannot decode {type_name}: not little-endian plain CDR '
                f'(header {payload[:4].hex() or "missing"})')
        if strict and payload[2:4] != b'\x00\x00':
            raise CdrError(f'cannot decode {type_name}: unexpected options {payload[2:4].hex()}')
        try:
            value, end = decoder(payload, 4)
        except CdrError as err:
            raise CdrError(f'cannot decode {type_name}: {err}') from None
        except (struct.error, ValueError, UnicodeDecodeError) as err:
            raise CdrError(f'cannot decode {type_name}: {type(err).__name__}: {err}') from err
        if strict and end != len(payload):
            raise CdrError(
                f'cannot decode {type_name}: {len(payload) - end} bytes after the last field')
        return value

    def default_message(self, type_name: str) -> dict[str, Any]:
        """
        Return a dict message with every field at zero, empty or ``False``.

        Fixed arrays hold that many zero values; sequences are empty. The
        default values of ``.msg`` files (``float64 w 1`` of
        ``geometry_msgs/msg/Quaternion``) are not known to rosbags' type store
        and not applied.
        """
        return {field.name: self._default_value(field) for field in self.spec(type_name).fields}

    def _default_value(self, field: FieldSpec) -> Any:
        prim = _PRIMS.get(field.base_type)
        fixed = field.array_size if field.array_kind is ArrayKind.FIXED else None
        if not field.is_array:
            if prim is not None:
                return False if prim.name == 'bool' else (
                    0.0 if prim.dtype.kind == 'f' else 0)
            if field.base_type == 'string':
                return ''
            return self.default_message(field.base_type)
        if prim is not None:
            count = fixed or 0
            return bytes(count) if prim.as_bytes else np.zeros(count, dtype=prim.dtype)
        if field.base_type == 'string':
            return [''] * (fixed or 0)
        return [self.default_message(field.base_type) for _ in range(fixed or 0)]


_DEFAULT_CODEC: list[CdrCodec] = []
_DEFAULT_LOCK = threading.Lock()


def default_codec() -> CdrCodec:
    """Return the process-wide codec over the default registry."""
    if not _DEFAULT_CODEC:
        with _DEFAULT_LOCK:
            if not _DEFAULT_CODEC:
                _DEFAULT_CODEC.append(CdrCodec())
    return _DEFAULT_CODEC[0]


def encode(type_name: str, message: Any) -> bytes:
    """Return the exact CDR bytes of ``message`` of ``type_name`` (default codec)."""
    return default_codec().encode(type_name, message)


def decode(type_name: str, data: Buffer, *, strict: bool = True) -> dict[str, Any]:
    """Decode CDR ``data`` of ``type_name`` into nested dicts (default codec)."""
    return default_codec().decode(type_name, data, strict=strict)


def default_message(type_name: str) -> dict[str, Any]:
    """Return a dict of ``type_name`` with all fields at zero values (default codec)."""
    return default_codec().default_message(type_name)
