"""Which values fit which topics: the message-type side of ``verify`` (schemas/kernel.xsd types).

A producer writes a *value type* (:mod:`runtime.verification.manifest`: a built-in type name, a
MessageType name, or one of the shapes ``number``, ``numbers``, ``mapping``, ``any``) onto a topic
that carries one type; a consumer reads one from it. Built-in numeric types are interchangeable
(a float64 sensor may feed a float32 topic), ``bool`` and ``time`` count as numbers (digital
channels and clocks read as numbers), and a vector of numbers fits a numeric topic or a MessageType
made only of numbers. A string fits only ``string``; a dict of fields only a MessageType; an array
(image) only ``bytes``.
"""

from __future__ import annotations

from collections.abc import Mapping

from ckmconf.model import BUILTIN_TYPES, MessageType

from .manifest import ANY, ARRAY, MAPPING, NUMBER, NUMBERS

NUMERIC = frozenset(BUILTIN_TYPES - {"string", "bytes"})
"""Built-in types a number fits (bool and time included)."""


def describe(value_type: str, size: int = 1) -> str:
    """A value type in words, for messages."""
    if value_type == NUMBER:
        return "single numbers"
    if value_type == NUMBERS:
        return f"vectors of {size} numbers" if size > 1 else "vectors of numbers"
    if value_type == MAPPING:
        return "dicts of fields"
    if value_type == ARRAY:
        return "arrays"
    if value_type in BUILTIN_TYPES:
        return f"{value_type} values"
    return f"{value_type} messages"


def _numeric_only(name: str, types: Mapping[str, MessageType], seen: frozenset[str] = frozenset()) -> bool:
    """Whether every field of MessageType ``name``, nested ones included, is a number."""
    if name in NUMERIC:
        return True
    message = types.get(name)
    if message is None or name in seen:
        return False
    return all(_numeric_only(f.type, types, seen | {name}) for f in message.fields)


def fits(written: str, carried: str, types: Mapping[str, MessageType]) -> bool:
    """Whether values of type ``written`` may travel on a topic of type ``carried``.

    Args:
        written: what the producer writes (or what the consumer expects to read).
        carried: the topic's ``type`` (a built-in type or a MessageType name).
        types: the system's MessageTypes by name.
    """
    if ANY in (written, carried):
        return True
    if carried not in BUILTIN_TYPES and carried not in types:
        return True  # an unknown topic type is the loader's error, not a mismatch to report again
    if written == NUMBER:
        return carried in NUMERIC
    if written == NUMBERS:
        return _numeric_only(carried, types)
    if written == MAPPING:
        return carried in types
    if written == ARRAY:
        return carried == "bytes"
    if written in NUMERIC and carried in NUMERIC:
        return True
    return written == carried
