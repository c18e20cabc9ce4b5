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
Message definitions from rosbags' type store, with no ROS message package installed.

:func:`default_registry` serves the ROS 2 Jazzy types built into rosbags;
:func:`registry_from_schema` serves the definitions in the ``ros2msg`` schema
text of an MCAP file instead. A :class:`MessageRegistry` gives the field layout
of a type (:meth:`~MessageRegistry.spec`, what the CDR codec is generated
from) and its complete ``ros2msg`` schema text (:meth:`~MessageRegistry.full_text`,
``Typestore.generate_msgdef(name, ros_version=2)``).

The schema text is generated from the field definitions, not copied from the
``.msg`` files as rosbag2 does: it declares the same constants, fields and
types, but has no comments, blank lines or default values, constants come
before fields, every message type is written ``pkg/Type``, dependencies follow
in order of first use, and no blank line precedes a separator line.
"""

import dataclasses
import enum
import functools
import re
from typing import Any

from rosbags.interfaces import Nodetype
from rosbags.typesys import get_types_from_msg, get_typestore, Stores, TypesysError
from rosbags.typesys.store import Typestore

from ..errors import ConeFeederError

__all__ = [
    'ArrayKind',
    'FieldSpec',
    'MessageDefinitionError',
    'MessageRegistry',
    'MessageSpec',
    'default_registry',
    'normalize_type_name',
    'registry_from_schema',
]

_TYPE_NAME_RE = re.compile(
    r'^(?P<pkg>[A-Za-z][A-Za-z0-9_]*)/(?:msg/)?(?P<name>[A-Za-z][A-Za-z0-9_]*)$')
#: The member rosidl (and rosbags) gives a message without fields; on the wire the
#: one ``uint8`` that CDR writes for an empty structure.
_PLACEHOLDER_FIELD = 'structure_needs_at_least_one_member'


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

    ``base_type`` is a primitive name (``float64``, ``string``...) or the name
    ``pkg/msg/Type`` of a nested message. ``array_size`` is the length of a
    fixed array or the bound of a bounded sequence, else ``None``.
    """

    name: str
    base_type: str
    array_kind: ArrayKind = ArrayKind.NONE
    array_size: int | None = None
    string_bound: int | None = None

    @property
    def is_primitive(self) -> bool:
        """Return whether the base type is a primitive (not a nested message)."""
        return '/' not in self.base_type

    @property
    def is_array(self) -> bool:
        """Return whether the field is a fixed array or a (bounded) sequence."""
        return self.array_kind is not ArrayKind.NONE


@dataclasses.dataclass(frozen=True)
class MessageSpec:
    """The fields of a message type, in wire order."""

    type_name: str
    fields: tuple[FieldSpec, ...]


def normalize_type_name(type_name: str) -> str:
    """Return the canonical ``pkg/msg/Type`` form of ``pkg/Type`` or ``pkg/msg/Type``."""
    match = _TYPE_NAME_RE.match(type_name.strip()) if isinstance(type_name, str) else None
    if match is None:
        raise MessageDefinitionError(
            f'invalid message type name {type_name!r}: expected "pkg/msg/Type" or "pkg/Type"')
    return f'{match["pkg"]}/msg/{match["name"]}'


def _field_spec(name: str, desc: Any) -> FieldSpec:
    """Return the field ``name`` of rosbags' field description ``desc``."""
    kind, size = ArrayKind.NONE, None
    if desc[0] in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        outer, (desc, count) = desc
        if outer == Nodetype.ARRAY:
            kind, size = ArrayKind.FIXED, count
        elif count:
            kind, size = ArrayKind.BOUNDED, count
        else:
            kind = ArrayKind.SEQUENCE
    if desc[0] == Nodetype.NAME:
        return FieldSpec(name, desc[1], kind, size)
    base, string_bound = desc[1]
    return FieldSpec(name, base, kind, size, string_bound or None)


class MessageRegistry:
    """The message types of one rosbags type store, with their layouts cached."""

    def __init__(self, typestore: Typestore, source: str = 'the type store') -> None:
        """Serve the types of ``typestore``; ``source`` names it in error messages."""
        self.typestore = typestore
        self.source = source
        self._specs: dict[str, MessageSpec] = {}

    def spec(self, type_name: str) -> MessageSpec:
        """Return the fields of ``type_name`` (cached)."""
        canonical = normalize_type_name(type_name)
        spec = self._specs.get(canonical)
        if spec is None:
            definition = self.typestore.fielddefs.get(canonical)
            if definition is None:
                raise MessageDefinitionError(
                    f'no message definition for {canonical} in {self.source}')
            fields = definition[1]
            if [name for name, _ in fields] == [_PLACEHOLDER_FIELD]:
                fields = []
            spec = MessageSpec(canonical, tuple(_field_spec(*field) for field in fields))
            self._specs[canonical] = spec
        return spec

    def resolve(self, type_name: str) -> dict[str, MessageSpec]:
        """Return the definitions of ``type_name`` and all its dependencies, by name."""
        result: dict[str, MessageSpec] = {}

        def visit(name: str, users: tuple[str, ...]) -> None:
            if name in users:
                chain = ' -> '.join(users + (name,))
                raise MessageDefinitionError(f'recursive message definition: {chain}')
            if name in result:
                return
            try:
                result[name] = spec = self.spec(name)
            except MessageDefinitionError as err:
                if not users:
                    raise
                raise MessageDefinitionError(f'{err} (used by {users[-1]})') from None
            for field in spec.fields:
                if not field.is_primitive:
                    visit(field.base_type, users + (name,))

        visit(normalize_type_name(type_name), ())
        return result

    def full_text(self, type_name: str) -> str:
        """Return the complete ``ros2msg`` schema text of ``type_name`` (see module doc)."""
        canonical = normalize_type_name(type_name)
        self.resolve(canonical)
        return self.typestore.generate_msgdef(canonical, ros_version=2)[0]


@functools.lru_cache(maxsize=1)
def default_registry() -> MessageRegistry:
    """Return the process-wide registry of rosbags' ROS 2 Jazzy types (created once)."""
    return MessageRegistry(
        get_typestore(Stores.ROS2_JAZZY), "rosbags' ROS 2 Jazzy type store")


def registry_from_schema(type_name: str, text: str) -> MessageRegistry:
    """
    Return a registry of the types defined by ``ros2msg`` schema text.

    ``text`` is the definition of ``type_name`` followed by those of its
    dependencies, each after a separator line of ``=`` and a ``MSG: pkg/Type``
    line, as in MCAP files written by rosbag2 or by this package. Besides
    those, the registry knows only ``builtin_interfaces/msg/Time`` and
    ``Duration`` (what ROS 1 style ``time`` and ``duration`` fields mean).
    Raises :class:`MessageDefinitionError` if the text does not parse or lacks
    a dependency.
    """
    canonical = normalize_type_name(type_name)
    typestore = get_typestore(Stores.EMPTY)
    try:
        typestore.register(get_types_from_msg(text, canonical))
    except TypesysError as err:
        raise MessageDefinitionError(f'invalid schema text of {canonical}: {err}') from None
    registry = MessageRegistry(typestore, f'the schema text of {canonical}')
    registry.resolve(canonical)
    return registry
