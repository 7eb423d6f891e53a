"""Signal payloads checked against their message type (thesis §5.3, Fig. 7.13; issue G point 5).

A plan ``<Signal type="T">`` carries data: the emitting state's behavior writes it on an
``<Output signal="…">`` and the engine checks it against ``T`` when the signal is sent. ``T`` is a
built-in type (``float64``, ``string`` …) or a ``<MessageType>``: then the payload is a mapping
with exactly the type's fields, each of its field type (a field with ``count`` other than 1 is a
list, of that length unless ``count`` is 0).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ckmconf.model.kernel import BUILTIN_TYPES, MessageType

_INTS = frozenset({"int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64"})


def _builtin(value: Any, type_name: str) -> bool:
    if type_name == "bool":
        return isinstance(value, bool)
    if type_name in _INTS:
        return isinstance(value, int) and not isinstance(value, bool)
    if type_name in ("float32", "float64", "time"):
        return isinstance(value, int | float) and not isinstance(value, bool)
    if type_name == "string":
        return isinstance(value, str)
    return isinstance(value, bytes | bytearray)  # "bytes"


def check_payload(value: Any, type_name: str, types: Mapping[str, MessageType], where: str = "payload") -> str | None:
    """Why ``value`` is not a ``type_name`` (None when it is one); ``where`` names it in the text."""
    if type_name in BUILTIN_TYPES:
        return None if _builtin(value, type_name) else f"{where} is {value!r}, not a {type_name}"
    message = types.get(type_name)
    if message is None:
        return f"{where}: unknown message type {type_name!r}"
    if not isinstance(value, Mapping):
        return f"{where} is {type(value).__name__} {value!r}, not a {type_name} (a mapping of its fields)"
    declared = {f.name: f for f in message.fields}
    extra = sorted(str(k) for k in value if k not in declared)
    if extra:
        return f"{where} has fields {', '.join(extra)} that {type_name} does not declare ({', '.join(declared)})"
    for name, field in declared.items():
        if name not in value:
            return f"{where} lacks field {name!r} of {type_name}"
        item = value[name]
        if field.count != 1:
            if not isinstance(item, list | tuple):
                return f"{where}.{name} is {item!r}, not a list of {field.type}"
            if field.count and len(item) != field.count:
                return f"{where}.{name} has {len(item)} items, {type_name} declares {field.count}"
            for index, element in enumerate(item):
                problem = check_payload(element, field.type, types, f"{where}.{name}[{index}]")
                if problem:
                    return problem
            continue
        problem = check_payload(item, field.type, types, f"{where}.{name}")
        if problem:
            return problem
    return None
