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
Find and parse ROS 2 ``.msg`` definitions without any ROS Python library.

A definition is looked up by type name (``sensor_msgs/msg/PointCloud2`` or
``sensor_msgs/PointCloud2``) as ``share/<pkg>/msg/<Type>.msg`` under every
prefix of ``AMENT_PREFIX_PATH`` and then under ``sys.prefix`` (where the PyPI
``ros-jazzy-*`` wheels install them).

The parser follows ``rosidl_adapter.parser``: comments start at the first
``#``, a line whose remainder after the type contains ``=`` is a constant,
``T[]`` / ``T[N]`` / ``T[<=N]`` are unbounded sequences, fixed arrays and
bounded sequences, ``string<=N`` is a bounded string, and an unqualified
non-primitive type names a message of the same package.

:meth:`MessageDefinitionRegistry.full_text` builds the complete ``ros2msg``
schema text byte for byte the way rosbag2 (``LocalMessageDefinitionSource``)
does: the raw text of the main file, then, depth first and each dependency
once in sorted order, a newline, a line of 80 ``=``, a line ``MSG: pkg/Type``
and the raw text of that dependency.
"""

import collections.abc
import dataclasses
import enum
import functools
import os
import pathlib
import re
import sys
import threading

from .errors import ConeFeederError

__all__ = [
    'PRIMITIVE_TYPES',
    'SEPARATOR',
    'ArrayKind',
    'ConstantSpec',
    'FieldSpec',
    'MessageDefinitionError',
    'MessageDefinitionRegistry',
    'MessageSpec',
    'default_registry',
    'default_search_prefixes',
    'get_full_text',
    'get_message_spec',
    'normalize_type_name',
    'parse_message_text',
    'short_type_name',
]

#: Primitive type names of the ``.msg`` language (``time``/``duration`` are aliases).
PRIMITIVE_TYPES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring',
})

#: ROS 1 compatibility aliases accepted by rosidl, mapped to their ROS 2 messages.
_LEGACY_ALIASES = {
    'time': 'builtin_interfaces/msg/Time',
    'duration': 'builtin_interfaces/msg/Duration',
}

#: Delimiter line (without newline) written between definitions in ``ros2msg`` text.
SEPARATOR = '=' * 80

_NAME_RE = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')
_TYPE_NAME_RE = re.compile(
    r'^(?P<pkg>[A-Za-z][A-Za-z0-9_]*)/(?:msg/)?(?P<name>[A-Za-z][A-Za-z0-9_]*)$')
_MAX_DEPTH = 64


class MessageDefinitionError(ConeFeederError):
    """A message definition is missing, malformed or cannot be resolved."""


class ArrayKind(enum.Enum):
    """How many values of its base type a field holds."""

    NONE = 'none'
    FIXED = 'fixed'
    BOUNDED = 'bounded'
    SEQUENCE = 'sequence'


@dataclasses.dataclass(frozen=True)
class FieldSpec:
    """
    One field of a message definition.

    ``base_type`` is a primitive name from :data:`PRIMITIVE_TYPES` or the
    canonical name ``pkg/msg/Type`` of a nested message. ``array_size`` is the
    length of a fixed array or the bound of a bounded sequence, else ``None``.
    ``default`` is the raw default value text of the ``.msg`` line, if any.
    """

    name: str
    base_type: str
    array_kind: ArrayKind = ArrayKind.NONE
    array_size: int | None = None
    string_bound: int | None = None
    default: str | None = None

    @property
    def is_primitive(self) -> bool:
        """Return whether the base type is a primitive (not a nested message)."""
        return self.base_type in PRIMITIVE_TYPES

    @property
    def is_array(self) -> bool:
        """Return whether the field is a fixed array or a (bounded) sequence."""
        return self.array_kind is not ArrayKind.NONE


@dataclasses.dataclass(frozen=True)
class ConstantSpec:
    """A constant of a message definition (irrelevant for encoding)."""

    name: str
    type_string: str
    value: str


@dataclasses.dataclass(frozen=True)
class MessageSpec:
    """
    A parsed message definition.

    ``dependencies`` lists the nested message types as ``pkg/Type`` (the form
    used in ``MSG:`` lines), sorted and without duplicates.
    """

    type_name: str
    fields: tuple[FieldSpec, ...]
    constants: tuple[ConstantSpec, ...]
    text: str
    path: pathlib.Path | None
    dependencies: tuple[str, ...]

    @property
    def package(self) -> str:
        """Return the package name of the type."""
        return self.type_name.split('/', 1)[0]


def normalize_type_name(type_name: str) -> str:
    """Return the canonical ``pkg/msg/Type`` form of ``pkg/Type`` or ``pkg/msg/Type``."""
    match = _TYPE_NAME_RE.match(type_name.strip()) if isinstance(type_name, str) else None
    if match is None:
        raise MessageDefinitionError(
            f'invalid message type name {type_name!r}: expected "pkg/msg/Type" or "pkg/Type"')
    return f'{match["pkg"]}/msg/{match["name"]}'


def short_type_name(type_name: str) -> str:
    """Return the ``pkg/Type`` form (as in ``MSG:`` lines) of a message type name."""
    package, _, name = normalize_type_name(type_name).split('/')
    return f'{package}/{name}'


def default_search_prefixes() -> list[pathlib.Path]:
    """
    Return the install prefixes searched for ``share/<pkg>/msg/<Type>.msg``.

    Those are the entries of ``AMENT_PREFIX_PATH`` in order, then ``sys.prefix``.
    """
    prefixes: list[pathlib.Path] = []
    for entry in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if entry:
            prefixes.append(pathlib.Path(entry))
    prefixes.append(pathlib.Path(sys.prefix))
    unique: list[pathlib.Path] = []
    for prefix in prefixes:
        if prefix not in unique:
            unique.append(prefix)
    return unique


def _parse_int(text: str, what: str) -> int:
    if not text.isdigit():
        raise ValueError(f'invalid {what} {text!r}')
    value = int(text)
    if value <= 0:
        raise ValueError(f'{what} must be positive, got {value}')
    return value


def _parse_field_type(
    type_string: str, package: str, type_exists: collections.abc.Callable[[str], bool] | None
) -> tuple[str, ArrayKind, int | None, int | None]:
    """Split a field type into base type, array kind, array size and string bound."""
    base = type_string
    kind = ArrayKind.NONE
    size: int | None = None
    if base.endswith(']'):
        base, bracket, inner = base[:-1].rpartition('[')
        if not bracket:
            raise ValueError(f'unbalanced brackets in type {type_string!r}')
        if inner == '':
            kind = ArrayKind.SEQUENCE
        elif inner.startswith('<='):
            kind = ArrayKind.BOUNDED
            size = _parse_int(inner[2:], 'sequence bound')
        else:
            kind = ArrayKind.FIXED
            size = _parse_int(inner, 'array size')
    string_bound: int | None = None
    for string_type in ('string', 'wstring'):
        if base.startswith(string_type + '<='):
            string_bound = _parse_int(base[len(string_type) + 2:], 'string bound')
            base = string_type
    if base in PRIMITIVE_TYPES:
        return base, kind, size, string_bound
    if base in _LEGACY_ALIASES:
        return _LEGACY_ALIASES[base], kind, size, None
    parts = base.split('/')
    if len(parts) == 1 and _NAME_RE.match(base):
        local = f'{package}/msg/{base}'
        if base == 'Header' and type_exists is not None and not type_exists(local):
            local = 'std_msgs/msg/Header'  # ROS 1 convention, kept for hand-written files
        return local, kind, size, None
    return normalize_type_name(base), kind, size, None


def parse_message_text(
    type_name: str, text: str, type_exists: collections.abc.Callable[[str], bool] | None = None
) -> tuple[tuple[FieldSpec, ...], tuple[ConstantSpec, ...]]:
    """
    Parse the text of a ``.msg`` file into its fields and constants.

    An unqualified type names a message of the same package. The one exception
    is ``Header`` when ``type_exists`` says the package has no ``Header``
    message: it then means ``std_msgs/msg/Header`` (the ROS 1 convention).
    Raises :class:`MessageDefinitionError` naming the type and the line for
    malformed content.
    """
    canonical = normalize_type_name(type_name)
    package = canonical.split('/', 1)[0]
    fields: list[FieldSpec] = []
    constants: list[ConstantSpec] = []
    names: set = set()
    for number, raw_line in enumerate(text.replace('\t', ' ').splitlines(), start=1):
        line = raw_line.split('#', 1)[0].strip()
        if not line:
            continue
        type_string, _, rest = line.partition(' ')
        rest = rest.lstrip()
        try:
            if not rest:
                raise ValueError('missing field name')
            if '=' in rest:
                name, _, value = rest.partition('=')
                name = name.rstrip()
                if not _NAME_RE.match(name):
                    raise ValueError(f'invalid constant name {name!r}')
                constants.append(ConstantSpec(name, type_string, value.strip()))
                continue
            name, _, default = rest.partition(' ')
            if not _NAME_RE.match(name):
                raise ValueError(f'invalid field name {name!r}')
            if name in names:
                raise ValueError(f'duplicate field name {name!r}')
            base, kind, size, bound = _parse_field_type(type_string, package, type_exists)
        except (ValueError, MessageDefinitionError) as err:
            raise MessageDefinitionError(
                f'{canonical}, line {number} ({raw_line.strip()!r}): {err}') from None
        names.add(name)
        fields.append(FieldSpec(name, base, kind, size, bound, default.strip() or None))
    return tuple(fields), tuple(constants)


class MessageDefinitionRegistry:
    """Look up, parse and cache message definitions under install prefixes."""

    def __init__(
        self, search_prefixes: collections.abc.Iterable[str | pathlib.Path] | None = None
    ) -> None:
        """Search ``search_prefixes`` (default: :func:`default_search_prefixes`)."""
        if search_prefixes is None:
            self._prefixes = tuple(default_search_prefixes())
        else:
            self._prefixes = tuple(pathlib.Path(prefix) for prefix in search_prefixes)
        self._specs: dict[str, MessageSpec] = {}
        self._full_texts: dict[str, str] = {}
        self._lock = threading.RLock()

    @property
    def search_prefixes(self) -> tuple[pathlib.Path, ...]:
        """Return the install prefixes searched, in order."""
        return self._prefixes

    def candidate_paths(self, type_name: str) -> list[pathlib.Path]:
        """Return the paths where the ``.msg`` file of ``type_name`` is looked for."""
        package, _, name = normalize_type_name(type_name).split('/')
        return [prefix / 'share' / package / 'msg' / f'{name}.msg' for prefix in self._prefixes]

    def find_file(self, type_name: str) -> pathlib.Path:
        """Return the path of the ``.msg`` file of ``type_name``."""
        candidates = self.candidate_paths(type_name)
        for path in candidates:
            if path.is_file():
                return path
        searched = ', '.join(str(path) for path in candidates) or '(no search prefixes)'
        raise MessageDefinitionError(
            f'no message definition for {normalize_type_name(type_name)}; searched: {searched}')

    def add_definition(self, type_name: str, text: str) -> MessageSpec:
        """Register a definition from text instead of a file (e.g. for tests or tools)."""
        canonical = normalize_type_name(type_name)
        spec = self._make_spec(canonical, text, None)
        with self._lock:
            self._specs[canonical] = spec
            self._full_texts.clear()
        return spec

    def get(self, type_name: str) -> MessageSpec:
        """Return the parsed definition of ``type_name`` (cached)."""
        canonical = normalize_type_name(type_name)
        spec = self._specs.get(canonical)
        if spec is not None:
            return spec
        with self._lock:
            spec = self._specs.get(canonical)
            if spec is None:
                path = self.find_file(canonical)
                try:
                    text = path.read_bytes().decode('utf-8')
                except (OSError, UnicodeDecodeError) as err:
                    raise MessageDefinitionError(
                        f'cannot read message definition of {canonical} from {path}: {err}'
                    ) from None
                spec = self._make_spec(canonical, text, path)
                self._specs[canonical] = spec
        return spec

    def exists(self, type_name: str) -> bool:
        """Return whether a definition of ``type_name`` is registered or can be found."""
        canonical = normalize_type_name(type_name)
        return canonical in self._specs or any(
            path.is_file() for path in self.candidate_paths(canonical))

    def _make_spec(self, canonical: str, text: str, path: pathlib.Path | None) -> MessageSpec:
        fields, constants = parse_message_text(canonical, text, self.exists)
        dependencies = sorted({
            short_type_name(field.base_type) for field in fields if not field.is_primitive})
        return MessageSpec(canonical, fields, constants, text, path, tuple(dependencies))

    def resolve(self, type_name: str) -> dict[str, MessageSpec]:
        """Return the definitions of ``type_name`` and all its dependencies, by canonical name."""
        result: dict[str, MessageSpec] = {}
        pending = [normalize_type_name(type_name)]
        while pending:
            name = pending.pop()
            if name in result:
                continue
            spec = self.get(name)
            result[name] = spec
            pending.extend(normalize_type_name(dep) for dep in spec.dependencies)
        return result

    def full_text(self, type_name: str) -> str:
        """Return the complete ``ros2msg`` schema text of ``type_name`` as rosbag2 writes it."""
        canonical = normalize_type_name(type_name)
        cached = self._full_texts.get(canonical)
        if cached is not None:
            return cached
        seen: set = set()

        def append(name: str, stack: tuple[str, ...]) -> str:
            if len(stack) > _MAX_DEPTH or name in stack:
                chain = ' -> '.join(stack + (name,))
                raise MessageDefinitionError(f'recursive message definition: {chain}')
            spec = self.get(name)
            parts = [spec.text]
            for dependency in spec.dependencies:
                if dependency in seen:
                    continue
                seen.add(dependency)
                parts.append(f'\n{SEPARATOR}\nMSG: {dependency}\n')
                parts.append(append(normalize_type_name(dependency), stack + (name,)))
            return ''.join(parts)

        text = append(canonical, ())
        self._full_texts[canonical] = text
        return text


@functools.lru_cache(maxsize=1)
def default_registry() -> MessageDefinitionRegistry:
    """Return the process-wide registry over :func:`default_search_prefixes` (created once)."""
    return MessageDefinitionRegistry()


def get_message_spec(type_name: str) -> MessageSpec:
    """Return the parsed definition of ``type_name`` from the default registry."""
    return default_registry().get(type_name)


def get_full_text(type_name: str) -> str:
    """Return the complete ``ros2msg`` schema text of ``type_name`` (default registry)."""
    return default_registry().full_text(type_name)
