"""A ``<Node>`` carried as configuration text between processes (code delegation, §3.1.2.5–6).

A busy node hands a running controller to an idle one as data, and that data is configuration:
the giver writes it with the binding (:func:`ckmconf.writer.dumps` of a ``<Part>`` holding the
message types used and one ``<Node>`` with the topics and the controller), and the taker reads it
back with :func:`ckmconf.load_bytes`: the schema, the records and the semantic checks a file
goes through, so a bad description is refused with the message ``ckm-validate`` would print for
the same element, ``ORIGIN:LINE:COL: XPATH: message``. Received text includes no file.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable

from .errors import ConfigError
from .loader import load_bytes
from .model import MessageType, Node
from .model.system import Content, Part
from .schema import SUPPORTED_MAJOR
from .source import Limits
from .writer import dumps

FRAGMENT_LIMITS = Limits(max_bytes=1024 * 1024, max_files=1, max_elements=100_000)
"""Bounds on received text: a controller's description is a few hundred bytes."""
_CARRIED = {"includes", "message_types", "nodes", "loc"}
"""What a fragment may hold: the rest of a Part (resources, missions, …) is not a node's."""


def dumps_node(node: Node, message_types: Iterable[MessageType] = ()) -> str:
    """The text of a ``<Part>`` holding ``message_types`` and ``node`` (written by the binding)."""
    part = Part(version=f"{SUPPORTED_MAJOR}.0", message_types=tuple(message_types), nodes=(node,))
    return dumps(part).decode("utf-8")


def loads_node(text: str | bytes, origin: str, limits: Limits = FRAGMENT_LIMITS) -> Node:
    """The one ``<Node>`` of a fragment, checked as the loader checks a file.

    Args:
        text: what :func:`dumps_node` wrote (or anything claiming to be it).
        origin: the name messages give the text (``<delegation from NODE>``).
        limits: bounds on the text.

    Raises:
        ConfigError: the first problem, at ``origin:LINE:COL`` and the element's path.
    """
    data = text.encode("utf-8") if isinstance(text, str) else text
    system = load_bytes(data, origin, limits=limits, includes=False)
    for field in dataclasses.fields(Content):
        if field.name not in _CARRIED and getattr(system, field.name) not in (None, ()):
            raise ConfigError.of(system, f"a node fragment holds message types and one Node, not {field.name}")
    if len(system.nodes) != 1:
        raise ConfigError.of(system, f"a node fragment holds exactly one Node, not {len(system.nodes)}")
    return system.nodes[0]


__all__ = ["FRAGMENT_LIMITS", "dumps_node", "loads_node"]
