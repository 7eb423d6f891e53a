"""Payload codecs on the wire: samples of some topic types serialised by a codec (issue L point 1).

The transports send a sample's value as msgpack (CKMultiPeer's TOPICDATA ``[topic, seq, stamp,
value]``, Zenoh's ``[seq, stamp, value]``). A :class:`WireCodec` installed on a transport
(``transport.codec``) serialises the values of the topic types it knows itself: the ROS 2 bridge
(:mod:`runtime.ros.wire`) sends a topic of a ROS 2 type as its CDR bytes. Such a value travels as
three elements, the bytes, the codec's name and the type (``[…, cdr, "cdr", "std_msgs/msg/Float64"]``),
so a receiver tells it from a plain value and decodes it without knowing the sender's configuration
(a monitor subscribing without a type too), and one without the codec drops it (logged once per
topic) rather than hand bytes to a subscriber expecting a message.

Local subscribers still get the very object published: only what leaves the process is encoded.
This module knows no codec itself (the network sits below the ROS bridge in the layers).
"""

from __future__ import annotations

import logging
from typing import Any, Protocol

LOG = logging.getLogger("ckm.wire")


class WireError(ValueError):
    """A coded value that cannot be decoded here (no codec, another codec, bad bytes)."""


class WireCodec(Protocol):
    """What a transport needs of a codec: which types it serialises, and how."""

    @property
    def name(self) -> str:
        """The codec's tag on the wire (``"cdr"``)."""
        ...

    def encodes(self, type_name: str) -> bool:
        """Whether values of topic type ``type_name`` travel serialised by this codec."""
        ...

    def encode(self, type_name: str, value: Any) -> bytes:
        """``value`` serialised; ValueError (or TypeError) when it does not fit the type."""
        ...

    def decode(self, type_name: str, data: bytes) -> Any:
        """The value ``data`` holds; ValueError when the bytes are not a ``type_name``."""
        ...


_warned: set[tuple[str, str]] = set()


def _warn_once(topic: str, message: str, *args: Any) -> None:
    if (topic, message) not in _warned:
        _warned.add((topic, message))
        LOG.warning(message, topic, *args)


def outgoing(codec: WireCodec | None, topic: str, type_name: str, value: Any) -> list[Any]:
    """The tail of a data frame for ``value``: ``[value]``, or ``[bytes, codec name, type]`` when coded.

    A value the codec refuses travels as it is (a warning per topic): the sample is not lost, only
    the remote ROS view of it.
    """
    if codec is None or not codec.encodes(type_name):
        return [value]
    try:
        return [codec.encode(type_name, value), codec.name, type_name]
    except (ValueError, TypeError) as error:
        _warn_once(topic, "%s: a value that does not fit its type travels uncoded: %s", error)
        return [value]


def incoming(codec: WireCodec | None, tail: list[Any]) -> Any:
    """The value a data frame's tail (``[value]`` or ``[bytes, codec name, type]``) carries.

    Raises:
        WireError: a coded value this transport cannot decode (no codec, another one, a type it
            does not serialise, bytes that are not of the type).
    """
    if len(tail) == 1:
        return tail[0]
    if len(tail) != 3 or not isinstance(tail[0], bytes) or not isinstance(tail[2], str):
        raise WireError(f"a malformed coded value ({len(tail)} elements)")
    data, tag, type_name = tail
    if codec is None or tag != codec.name:
        raise WireError(f"a {tag!r}-coded value and no such codec here")
    if not codec.encodes(type_name):
        raise WireError(f"a {tag!r}-coded value on a topic of type {type_name!r}, which {tag} does not carry")
    try:
        return codec.decode(type_name, data)
    except (ValueError, TypeError) as error:
        raise WireError(str(error)) from error


def undecodable(topic: str, error: WireError) -> None:
    """Log (once per topic and reason) a received value dropped because it cannot be decoded."""
    _warn_once(topic, "%s: a received value is dropped: %s", error)
