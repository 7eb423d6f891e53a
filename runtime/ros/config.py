"""The ROS 2 side of a configuration: which ROS type each ``<Topic>`` travels as (issue L points 1, 2).

A ``<Topic type>`` (schemas/kernel.xsd ``TopicTypeName``) is one of

- a **ROS 2 type** ``package/msg/Name``: a standard one of the store, or a custom one read from
  ``package/msg/Name.msg`` next to the configuration file declaring the topic
  (:mod:`ckmconf.rostypes`); it travels as itself;
- a **MessageType** of the system: it travels as a generated ``ckm_msgs/msg/<Name>`` whose ``.msg``
  definition follows the Fields (:func:`message_definition`: numbers and ``bool``/``string`` as
  themselves, ``time`` → ``builtin_interfaces/Time``, ``bytes`` → ``uint8[]``, ``count="0"`` → an
  unbounded array ``T[]``, ``count="N"`` → ``T[N]``, a nested MessageType → its generated message;
  field names in snake_case as ROS wants them). A MessageType that contains itself (through a
  ``count="0"`` list), or holds one that does, has no ROS equivalent and travels as :data:`BYTES_TYPE`;
- a **built-in type**: ``std_msgs/msg/Float64``, ``Int32``, ``Bool``, ``String`` … (:data:`BUILTIN_ROS`),
  ``time`` as ``builtin_interfaces/msg/Time``, ``bytes`` as :data:`BYTES_TYPE`.

A CKM value that is not a dict stands for the ``data`` field of a ROS type that has one (a float on
``std_msgs/msg/Float64``, a vector on ``std_msgs/msg/Float64MultiArray``), the other fields taking
their defaults (decision D131). :meth:`ConfigRosTypes.value_problems` is what ``verify`` checks a
producer's or consumer's value type with (:func:`runtime.ros.compat.compatibility_problems` for
MessageTypes); :meth:`ConfigRosTypes.payload` turns a CKM value into the payload
:mod:`runtime.ros.convert` encodes (a standard kind's planar result as its interface's standard
type: :mod:`runtime.ros.interface_types`, D279).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from typing import Any

import msgpack
import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys import get_types_from_msg

from ckmconf.model import BUILTIN_TYPES, MessageType, System, Topic
from ckmconf.rostypes import custom_msg_file, is_ros_type

from ..resources import codec
from ..verification.manifest import ANY, ARRAY, MAPPING, NUMBER, NUMBERS
from .compat import compatibility_problems, field_problems, snake_case
from .convert import _DEFAULT_ENCODING, IMAGE, TIME_TYPES
from .interface_types import to_standard
from .types import RosTypeError, RosTypes

CKM_PACKAGE = "ckm_msgs"
BYTES_TYPE = "ckm_msgs/msg/Bytes"
"""Raw bytes (``uint8[] data``): a ``bytes`` topic; any other value is stored as its msgpack encoding
of :mod:`runtime.resources.codec`."""

BUILTIN_ROS = {
    **{n: f"std_msgs/msg/{n.capitalize()}" for n in ("int8", "int16", "int32", "int64", "float32", "float64")},
    **{n: f"std_msgs/msg/UInt{n[4:]}" for n in ("uint8", "uint16", "uint32", "uint64")},
    "bool": "std_msgs/msg/Bool",
    "string": "std_msgs/msg/String",
    "bytes": BYTES_TYPE,
    "time": "builtin_interfaces/msg/Time",
}
"""The ROS type a topic of each built-in CKM type travels as."""

_NUMBERS = frozenset({"int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64", "float32", "float64"})
_SCALARS = _NUMBERS | {"bool", "string"}


def plain(value: Any) -> Any:
    """A value in :mod:`runtime.resources.codec`'s plain form (what sensors of vectors and services
    publish: arrays as ``{"~nd": …}``) rebuilt with its arrays; any other value as it is."""
    if isinstance(value, dict | list):
        try:
            return codec.decode(value)
        except codec.CodecError:  # already holds arrays or tuples: not the plain form
            return value
    return value


def all_topics(system: System) -> list[tuple[Topic, str | None]]:
    """Every configured ``<Topic>`` with the node declaring it (None at system level)."""
    return [(t, None) for t in system.topics] + [(t, n.name) for n in system.nodes for t in n.topics]


def ros_field_name(name: str) -> str:
    """A CKM field name as a ROS field name: snake_case, ``-`` → ``_``, starting with a letter."""
    text = re.sub(r"_+", "_", re.sub(r"[^a-z0-9_]", "_", snake_case(name))).strip("_")
    return text if text[:1].isalpha() else f"f_{text}".rstrip("_")


def ros_message_name(name: str) -> str:
    """A CKM MessageType name as a ROS message name: CamelCase, starting with a letter."""
    camel = "".join(part[:1].upper() + part[1:] for part in re.split(r"[-_]+", name) if part)
    return camel if camel[:1].isalpha() else f"T{camel}"


class ConfigRosTypes:
    """The ROS types of one configuration: custom ``.msg`` files, generated ``ckm_msgs`` types.

    Args:
        system: the loaded system.
        ros: the store to extend (a fresh Jazzy store by default).

    ``problems`` holds, per ROS type name a topic names, why it could not be loaded.
    """

    def __init__(self, system: System, ros: RosTypes | None = None) -> None:
        self.ros = ros or RosTypes()
        self.message_types: dict[str, MessageType] = {m.name: m for m in system.message_types}
        self.problems: dict[str, str] = {}
        self.generated: dict[str, str] = {}  # MessageType → ROS type
        self.field_names: dict[str, dict[str, str]] = {}  # generated ROS type → CKM field → ROS field
        if BYTES_TYPE not in self.ros:
            self.ros.add_msg(BYTES_TYPE, "uint8[] data\n")
        for topic, _ in all_topics(system):
            if is_ros_type(topic.type) and topic.type not in self.ros and topic.type not in self.problems:
                try:
                    self._load_custom(topic.type, topic.loc.file if topic.loc else None, ())
                except RosTypeError as error:
                    self.problems[topic.type] = str(error)
        self._generate(system.message_types)

    # ------------------------------------------------------------------ type names

    def ros_type_of(self, ckm_type: str) -> str:
        """The ROS type a topic of ``ckm_type`` travels as (RosTypeError when there is none)."""
        if is_ros_type(ckm_type):
            if ckm_type not in self.ros:
                raise RosTypeError(self.problems.get(ckm_type, f"unknown ROS 2 type {ckm_type!r}"))
            return ckm_type
        if ckm_type in BUILTIN_ROS:
            return BUILTIN_ROS[ckm_type]
        if ckm_type in self.generated:
            return self.generated[ckm_type]
        raise RosTypeError(f"no ROS 2 type for CKM type {ckm_type!r}")

    def _load_custom(self, name: str, declared_in: str | None, chain: tuple[str, ...]) -> None:
        """Register custom type ``name`` from its ``.msg`` file, custom types it names first."""
        path = custom_msg_file(name, declared_in)
        if name in chain:
            raise RosTypeError(f"{path}: {name} contains itself ({' → '.join((*chain, name))})")
        try:
            text = path.read_text(encoding="utf-8")
            definitions = get_types_from_msg(text, name)
        except OSError as error:
            raise RosTypeError(f"{path}: cannot read the definition of {name}: {error.strerror}") from error
        except Exception as error:  # rosbags raises its own parser errors
            raise RosTypeError(
                f"{path}: cannot parse the .msg definition of {name}: {' '.join(str(error).split())}"
            ) from error
        for _, fields in definitions.values():
            for _, desc in fields:
                nested = _nested_name(desc)
                if nested is not None and nested not in self.ros and nested not in definitions:
                    self._load_custom(nested, declared_in, (*chain, name))
        self.ros.add_msg(name, text)

    def _generate(self, message_types: Iterable[MessageType]) -> None:
        """Register a ``ckm_msgs`` type per MessageType, nested ones first; recursive ones → bytes."""
        pending = {m.name: m for m in message_types}
        taken = {BYTES_TYPE}
        for name in pending:
            base = f"{CKM_PACKAGE}/msg/{ros_message_name(name)}"
            ros_name, index = base, 2
            while ros_name in taken or ros_name in self.ros:
                ros_name, index = f"{base}{index}", index + 1
            taken.add(ros_name)
            self.generated[name] = ros_name
        while pending:
            ready = [m for m in pending.values() if all(f.type not in pending or f.type == m.name for f in m.fields)]
            ready = [m for m in ready if all(f.type != m.name for f in m.fields)]
            if not ready:  # what is left contains itself, directly or not: no ROS message can hold it
                for name in pending:
                    self.generated[name] = BYTES_TYPE
                break
            for message in ready:
                del pending[message.name]
                text, names = message_definition(message, self.generated)
                self.ros.add_msg(self.generated[message.name], text)
                self.field_names[self.generated[message.name]] = names

    # ------------------------------------------------------------------ verify

    def value_problems(self, written: str, ros_type: str) -> list[str]:
        """Why values of the value type ``written`` (``runtime.verification.manifest``) do not fit
        the ROS type ``ros_type``; empty when they do, or when the type is unknown (reported at the topic)."""
        if ros_type not in self.ros or written in (ANY, MAPPING) or written == ros_type:
            return []
        if written == ARRAY:
            return [] if ros_type == IMAGE else [f"arrays travel only as {IMAGE}"]
        if is_ros_type(written):
            return [f"a {written} is not a {ros_type}"]
        if written in self.message_types or written == "time":
            return compatibility_problems(written, ros_type, self.ros, self.message_types)
        data = dict(self.ros.fields(ros_type)).get("data")
        if data is None:
            return [f"{ros_type} has no 'data' field to hold them (a ROS-typed topic carries a dict of its fields)"]
        kind, detail = data
        if written == NUMBER:
            ok = kind == Nodetype.BASE and detail[0] in _NUMBERS
            return [] if ok else ["its 'data' field is not a number"]
        if written == NUMBERS:
            ok = kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) and detail[0][0] == Nodetype.BASE
            return [] if ok and detail[0][1][0] in _NUMBERS else ["its 'data' field is not an array of numbers"]
        if written in BUILTIN_TYPES:
            return field_problems(written, 1, data, self.ros, self.message_types, f"{ros_type}.data")
        return [f"a {written} is not a {ros_type}"]

    # ------------------------------------------------------------------ recording

    def payload(self, ros_type: str, value: Any) -> Any:
        """The payload of :func:`runtime.ros.convert.to_message` a CKM ``value`` stands for."""
        if ros_type == BYTES_TYPE:
            if isinstance(value, Mapping) and set(value) == {"data"}:
                value = value["data"]
            if isinstance(value, bytes | bytearray | memoryview):
                return {"data": bytes(value)}
            return {"data": msgpack.packb(codec.encode(value), use_bin_type=True)}
        if ros_type in TIME_TYPES or (ros_type == IMAGE and isinstance(value, np.ndarray)):
            return value
        fields = dict(self.ros.fields(ros_type))
        if isinstance(value, np.ndarray) and value.ndim in (2, 3) and "data" in fields:
            return _image_fields(value, fields)  # an image-like MessageType (width, height, data …)
        if not isinstance(value, Mapping):
            return {"data": value} if "data" in fields else value  # else to_message says what is wrong
        names = self.field_names.get(ros_type)
        if names is None:  # CKM's planar conventions as the standard type's fields
            value = to_standard(ros_type, fields, value)
        result: dict[Any, Any] = {}
        for key, item in value.items():
            # generated types: the names they were made with; others: as written, or in snake_case
            target = names.get(str(key), key) if names is not None else key if key in fields else snake_case(str(key))
            desc = fields.get(str(target))
            result[target] = item if desc is None else self._field(desc, item)
        return result

    def _field(self, desc: Any, item: Any) -> Any:
        kind, detail = desc
        if kind == Nodetype.NAME:
            return self.payload(detail, item)
        nested = kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) and detail[0][0] == Nodetype.NAME
        if nested and isinstance(item, list | tuple):
            return [self.payload(detail[0][1], element) for element in item]
        return item


def _image_fields(image: np.ndarray, fields: Mapping[str, Any]) -> dict[str, Any]:
    """An (H, W) or (H, W, C) array as the fields of an image-like message: its pixels in ``data``,
    and ``height``, ``width``, ``encoding``, ``step``, ``is_bigendian`` where the type has them."""
    height, width = image.shape[:2]
    channels = 1 if image.ndim == 2 else image.shape[2]
    code = image.dtype.newbyteorder("<").str[1:]
    data = np.ascontiguousarray(image).astype("<" + code, copy=False)
    kind, detail = fields["data"]
    element = detail[0][1][0] if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) and detail[0][0] == Nodetype.BASE else ""
    known = {
        "height": height,
        "width": width,
        "encoding": _DEFAULT_ENCODING.get((code, channels), f"{code}x{channels}"),
        "step": width * channels * data.dtype.itemsize,
        "is_bigendian": 0,
        # raw bytes for a bytes/uint8[] field, the values themselves for a numeric array field
        "data": data.tobytes() if element in ("uint8", "byte", "char") else data.reshape(-1),
    }
    return {name: value for name, value in known.items() if name in fields}


def _nested_name(desc: Any) -> str | None:
    """The message type a field description names (itself or as array elements), if any."""
    kind, detail = desc
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        kind, detail = detail[0]
    return str(detail) if kind == Nodetype.NAME else None


def message_definition(message: MessageType, generated: Mapping[str, str]) -> tuple[str, dict[str, str]]:
    """The ``.msg`` text of a MessageType and its CKM → ROS field names.

    Args:
        message: the MessageType.
        generated: the ROS type of every MessageType it may name.
    """
    lines, names = [f"# CKM MessageType {message.name} (generated by CKM)"], {}
    used: set[str] = set()
    for field in message.fields:
        name, index = ros_field_name(field.name), 2
        while name in used:
            name, index = f"{ros_field_name(field.name)}_{index}", index + 1
        used.add(name)
        names[field.name] = name
        if field.type == "bytes" and field.count == 1:
            type_text = "uint8[]"
        else:
            if field.type == "time":
                element = "builtin_interfaces/Time"
            elif field.type == "bytes":
                element = "ckm_msgs/Bytes"
            elif field.type in _SCALARS:
                element = field.type
            else:
                element = generated[field.type].replace("/msg/", "/")
            type_text = element if field.count == 1 else f"{element}[{field.count or ''}]"
        unit = f"  # {field.unit}" if field.unit else ""
        lines.append(f"{type_text} {name}{unit}")
    return "\n".join(lines) + "\n", names
