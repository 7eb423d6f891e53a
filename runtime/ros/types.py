"""ROS 2 message types through the ``rosbags`` type store: CDR codec, type hashes, DDS names (issue L).

A CKM topic may carry a ROS 2 type named as ``package/msg/Name`` (thesis §4.4.1, the ROS
MultiPeer Architecture, for today's ROS 2 users). :class:`RosTypes` holds one type store: the
standard interfaces of a ROS 2 distribution (std_msgs, geometry_msgs, sensor_msgs, nav_msgs,
tf2_msgs … as shipped by ``rosbags``) plus custom ``.msg`` definitions given as text or files.

On the wire a message is CDR, little endian, behind the 4-byte encapsulation header
``00 01 00 00`` (CDR_LE), as every ROS 2 RMW and rosbag2 writes it. :meth:`RosTypes.rihs01`
is the REP-2016 type hash (``RIHS01_`` + sha256 of the canonical JSON of the type description),
computed here from the field definitions; rmw_zenoh puts it in key expressions and rosbag2 in
``metadata.yaml``.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Any

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

CDR_LE_HEADER = b"\x00\x01\x00\x00"
"""The encapsulation header of little-endian plain CDR (what ROS 2 publishes)."""

_TYPE_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*/(msg|srv|action)/[A-Za-z][A-Za-z0-9_]*$")

# type_description_interfaces/msg/FieldType ids (REP-2016); arrays add 48, bounded sequences 96,
# unbounded sequences 144.
_FIELD_TYPE_IDS = {
    "int8": 2,
    "uint8": 3,
    "int16": 4,
    "uint16": 5,
    "int32": 6,
    "uint32": 7,
    "int64": 8,
    "uint64": 9,
    "float32": 10,
    "float64": 11,
    "float128": 12,
    "char": 13,
    "bool": 15,
    "byte": 16,
    "string": 17,
}
_NESTED, _BOUNDED_STRING = 1, 21
_ARRAY, _BOUNDED_SEQUENCE, _SEQUENCE = 48, 96, 144
_EMPTY_MEMBER = ("structure_needs_at_least_one_member", (Nodetype.BASE, ("uint8", 0)))


class RosTypeError(ValueError):
    """An unknown or malformed ROS type, or bytes that are not a CDR message of the named type."""


def is_ros_type_name(name: str) -> bool:
    """Whether ``name`` is spelt like a ROS 2 interface type (``package/msg/Name``)."""
    return bool(_TYPE_NAME.match(name))


def dds_type_name(type_name: str) -> str:
    """The DDS name of a ROS 2 type, as rmw_zenoh puts it in key expressions.

    ``std_msgs/msg/String`` → ``std_msgs::msg::dds_::String_``.
    """
    if not is_ros_type_name(type_name):
        raise RosTypeError(f"{type_name!r} is not a ROS 2 type name (package/msg/Name)")
    package, kind, name = type_name.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def ros_type_name(dds_name: str) -> str:
    """The ROS 2 type name of a DDS type name (the inverse of :func:`dds_type_name`)."""
    match = re.fullmatch(r"([A-Za-z][A-Za-z0-9_]*)::(msg|srv|action)::dds_::([A-Za-z][A-Za-z0-9_]*)_", dds_name)
    if not match:
        raise RosTypeError(f"{dds_name!r} is not a DDS type name (package::msg::dds_::Name_)")
    return "/".join(match.groups())


class RosTypes:
    """One ROS 2 type store: the standard interfaces of a distribution plus custom definitions.

    Args:
        distro: the ``rosbags`` store to start from (Jazzy by default: the current LTS).
    """

    def __init__(self, distro: Stores = Stores.ROS2_JAZZY) -> None:
        self.distro = distro
        self.store: Typestore = get_typestore(distro)

    # ------------------------------------------------------------------ definitions

    def __contains__(self, type_name: object) -> bool:
        return isinstance(type_name, str) and type_name in self.store.fielddefs

    def names(self) -> list[str]:
        """Every known type name, sorted."""
        return sorted(self.store.fielddefs)

    def add_msg(self, type_name: str, text: str) -> None:
        """Register a custom ``.msg`` definition ``text`` as ``type_name`` (``pkg/msg/Name``).

        Field types it names must be known already or registered in the same call order.
        """
        if not is_ros_type_name(type_name):
            raise RosTypeError(f"{type_name!r} is not a ROS 2 type name (package/msg/Name)")
        try:
            definitions = get_types_from_msg(text, type_name)
        except Exception as error:  # rosbags raises its own parser errors
            raise RosTypeError(f"{type_name}: cannot parse the .msg definition: {error}") from error
        for _, fields in definitions.values():
            for field_name, desc in fields:
                nested = _nested_name(desc)
                if nested and nested not in self.store.fielddefs and nested not in definitions:
                    raise RosTypeError(f"{type_name}: field {field_name!r} names unknown type {nested!r}")
        self.store.register(definitions)

    def add_msg_file(self, path: str | Path, type_name: str | None = None) -> str:
        """Register the ``.msg`` file at ``path``; its type name defaults to ``<pkg>/msg/<stem>``
        where ``<pkg>`` is the folder above ``msg/``. Returns the type name."""
        path = Path(path)
        if type_name is None:
            if path.parent.name != "msg":
                raise RosTypeError(f"{path}: name the type, or keep the file in <package>/msg/")
            type_name = f"{path.parent.parent.name}/msg/{path.stem}"
        self.add_msg(type_name, path.read_text(encoding="utf-8"))
        return type_name

    def fields(self, type_name: str) -> list[tuple[str, Any]]:
        """The rosbags field definitions of ``type_name``: ``[(name, (nodetype, detail)), …]``."""
        self._known(type_name)
        return list(self.store.fielddefs[type_name][1])

    def message_class(self, type_name: str) -> Any:
        """The dataclass ``rosbags`` builds messages of ``type_name`` with."""
        self._known(type_name)
        return self.store.types[type_name]

    def msgdef(self, type_name: str) -> str:
        """The ``ros2msg`` schema text of ``type_name`` with its dependencies (MCAP, rosbag2)."""
        self._known(type_name)
        text, _ = self.store.generate_msgdef(type_name, ros_version=2)
        return text

    # ------------------------------------------------------------------ codec

    def encode(self, type_name: str, message: Any) -> bytes:
        """``message`` (a ``rosbags`` message object) as CDR_LE bytes with the encapsulation header."""
        self._known(type_name)
        if getattr(message, "__msgtype__", None) != type_name:
            raise RosTypeError(f"expected a {type_name} message, got {type(message).__name__}")
        try:
            return bytes(self.store.serialize_cdr(message, type_name))
        except Exception as error:
            raise RosTypeError(f"cannot serialise {type_name}: {error}") from error

    def decode(self, type_name: str, data: bytes | memoryview) -> Any:
        """The ``rosbags`` message ``data`` holds; RosTypeError on a bad header or truncated data."""
        self._known(type_name)
        raw = bytes(data)
        if len(raw) < 4 or raw[:2] not in (b"\x00\x00", b"\x00\x01"):
            raise RosTypeError(f"{type_name}: {len(raw)} bytes without a plain CDR encapsulation header")
        try:
            return self.store.deserialize_cdr(raw, type_name)
        except Exception as error:
            raise RosTypeError(f"{type_name}: cannot deserialise {len(raw)} bytes: {error}") from error

    # ------------------------------------------------------------------ REP-2016 type hash

    def type_description(self, type_name: str) -> dict[str, Any]:
        """The hashable type description of REP-2016: the type and every type it refers to
        (sorted by name), without default values or comments."""
        structs: dict[str, dict[str, Any]] = {}
        pending = [type_name]
        while pending:
            name = pending.pop()
            if name in structs:
                continue
            fields = self.fields(name) or [_EMPTY_MEMBER]
            described = [_describe_field(field_name, desc) for field_name, desc in fields]
            structs[name] = {"type_name": name, "fields": described}
            pending.extend(f["type"]["nested_type_name"] for f in described if f["type"]["nested_type_name"])
        return {
            "type_description": structs[type_name],
            "referenced_type_descriptions": [structs[n] for n in sorted(structs) if n != type_name],
        }

    def rihs01(self, type_name: str) -> str:
        """The RIHS01 type hash: sha256 over the canonical JSON (``json.dumps`` with its default
        ``", "`` / ``": "`` separators, keys in declaration order) of :meth:`type_description`."""
        canonical = json.dumps(self.type_description(type_name))
        return "RIHS01_" + hashlib.sha256(canonical.encode("utf-8")).hexdigest()

    def _known(self, type_name: str) -> None:
        if type_name not in self.store.fielddefs:
            hint = "" if is_ros_type_name(type_name) else " (ROS 2 types are named package/msg/Name)"
            raise RosTypeError(f"unknown ROS 2 type {type_name!r}{hint}")


def _nested_name(desc: Any) -> str | None:
    kind, detail = desc
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        kind, detail = detail[0]
    return detail if kind == Nodetype.NAME else None


def _describe_field(name: str, desc: Any) -> dict[str, Any]:
    kind, detail = desc
    offset, capacity = 0, 0
    if kind == Nodetype.ARRAY:
        offset, capacity = _ARRAY, detail[1]
        kind, detail = detail[0]
    elif kind == Nodetype.SEQUENCE:
        capacity = detail[1]
        offset = _BOUNDED_SEQUENCE if capacity else _SEQUENCE
        kind, detail = detail[0]
    nested, string_capacity = "", 0
    if kind == Nodetype.NAME:
        type_id, nested = offset + _NESTED, detail
    elif detail[0] == "string" and detail[1]:
        type_id, string_capacity = offset + _BOUNDED_STRING, detail[1]
    else:
        type_id = offset + _FIELD_TYPE_IDS[detail[0]]
    return {
        "name": name,
        "type": {
            "type_id": type_id,
            "capacity": capacity,
            "string_capacity": string_capacity,
            "nested_type_name": nested,
        },
    }
