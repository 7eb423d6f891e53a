"""Whether a CKM ``<MessageType>`` fits a ROS 2 type (issue L point 1, for ``verify``).

A CKM message type (schemas/kernel.xsd ``<MessageType>``/``<Field>``) fits a ROS type when every
one of its fields has a ROS field to go to, of a type its values convert to without loss:

- names match as written or after camelCase → snake_case (``angleMin`` → ``angle_min``);
- numbers go to numbers that hold every value (numpy ``can_cast(…, "safe")``: ``float32`` →
  ``float64`` fits, ``float64`` → ``float32`` does not); ``bool``, ``string`` go to themselves;
  ``bytes`` to ``uint8[]``/``byte[]``; ``time`` to ``builtin_interfaces/msg/Time``;
- a nested MessageType goes to a nested ROS message it fits, recursively;
- ``count="1"`` goes to a scalar, ``count="N"`` to an array of N or a sequence that holds N,
  ``count="0"`` (variable) to an unbounded sequence.

ROS fields the CKM type does not have are no problem: they take their defaults.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype

from ckmconf.model import BUILTIN_TYPES, MessageType

from .types import RosTypes

_NUMBERS = frozenset({"int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64", "float32", "float64"})


def snake_case(name: str) -> str:
    """``angleMin`` → ``angle_min`` (ROS field names are snake_case)."""
    return re.sub(r"(?<=[a-z0-9])([A-Z])", r"_\1", name).lower()


def compatibility_problems(
    ckm_type: str, ros_type: str, ros: RosTypes, ckm_types: Mapping[str, MessageType], where: str | None = None
) -> list[str]:
    """Why values of the CKM type ``ckm_type`` cannot travel as ``ros_type`` (empty when they can).

    Args:
        ckm_type: a built-in type name or a MessageType name of the configuration.
        ros_type: a ROS 2 type name known to ``ros``.
        ros: the type store.
        ckm_types: the configuration's MessageTypes by name.
        where: the name used in messages (defaults to ``ckm_type``).
    """
    where = where or ckm_type
    if ros_type not in ros:
        return [f"{where}: unknown ROS 2 type {ros_type!r}"]
    if ckm_type in BUILTIN_TYPES:
        if ckm_type == "time" and ros_type == "builtin_interfaces/msg/Time":
            return []
        return [f"{where}: a {ckm_type} is not a {ros_type} message"]
    message = ckm_types.get(ckm_type)
    if message is None:
        return [f"{where}: unknown CKM message type {ckm_type!r}"]
    ros_fields = dict(ros.fields(ros_type))
    problems: list[str] = []
    for field in message.fields:
        target = field.name if field.name in ros_fields else snake_case(field.name)
        if target not in ros_fields:
            also = f" or {target!r}" if target != field.name else ""
            problems.append(f"{where}.{field.name}: {ros_type} has no field {field.name!r}{also}")
            continue
        place = f"{where}.{field.name}"
        problems += field_problems(field.type, field.count, ros_fields[target], ros, ckm_types, place)
    return problems


def field_problems(
    ckm: str, count: int, desc: Any, ros: RosTypes, ckm_types: Mapping[str, MessageType], where: str
) -> list[str]:
    """Why ``count`` values of CKM type ``ckm`` cannot fill a ROS field of rosbags description ``desc``."""
    kind, detail = desc
    if ckm == "bytes" and count == 1:
        if kind == Nodetype.SEQUENCE and detail[0][0] == Nodetype.BASE and detail[0][1][0] in ("uint8", "byte"):
            return []
        return [f"{where}: bytes need a uint8[] or byte[] sequence"]
    if count == 1:
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            return [f"{where}: one {ckm} cannot fill an array or sequence"]
        return _element_problems(ckm, kind, detail, ros, ckm_types, where)
    if kind in (Nodetype.BASE, Nodetype.NAME):
        many = "a list" if count == 0 else f"{count} values"
        return [f"{where}: {many} of {ckm} cannot fill a single field"]
    (element_kind, element), size = detail
    container = "an array of" if kind == Nodetype.ARRAY else "a sequence of at most"
    if count == 0 and size:
        return [f"{where}: a variable-length list cannot fill {container} {size}"]
    too_many = kind == Nodetype.SEQUENCE and size and size < count
    if count > 0 and ((kind == Nodetype.ARRAY and size != count) or too_many):
        return [f"{where}: {count} values do not fit {container} {size}"]
    return _element_problems(ckm, element_kind, element, ros, ckm_types, where)


def _element_problems(
    ckm: str, kind: Nodetype, detail: object, ros: RosTypes, ckm_types: Mapping[str, MessageType], where: str
) -> list[str]:
    if kind == Nodetype.NAME:
        assert isinstance(detail, str)
        if ckm == "time":
            return [] if detail == "builtin_interfaces/msg/Time" else [f"{where}: a time cannot fill a {detail}"]
        if ckm in BUILTIN_TYPES:
            return [f"{where}: a {ckm} cannot fill a {detail} message"]
        return compatibility_problems(ckm, detail, ros, ckm_types, where)
    base = detail[0]  # type: ignore[index]
    if ckm in _NUMBERS and base in _NUMBERS:
        if np.can_cast(np.dtype(ckm), np.dtype(base), "safe"):
            return []
        return [f"{where}: a {ckm} does not fit a {base} without loss"]
    if ckm == base and ckm in ("bool", "string"):
        return []
    return [f"{where}: a {ckm} cannot fill a {base}"]
