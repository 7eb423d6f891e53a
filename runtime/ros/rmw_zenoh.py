"""The rmw_zenoh naming and wire conventions, as pure functions (issue L point 3).

So that ROS 2 nodes running ``rmw_zenoh_cpp`` see CKM topics on the Zenoh transport and CKM sees
theirs (thesis §4.4.1). Matches rmw_zenoh_cpp's design document (``docs/design.md`` of
ros2/rmw_zenoh, the version with the 33-byte attachment: Jazzy releases from 0.2.4 on, Kilted,
Rolling); ``docs/ros.md`` says more. Everything here is text and bytes; no Zenoh session is opened.

- Data key expression: ``<domain_id>/<fully qualified name without the leading />/<DDS type
  name>/<RIHS01 type hash>``, e.g. ``0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66…``.
- Liveliness tokens: ``@ros2_lv/<domain>/<session id>/<node id>/<entity id>/<kind>/<enclave>/
  <namespace>/<node name>[/<topic>/<type>/<hash>/<qos>]`` with every ``/`` inside a part
  replaced by ``%`` (an empty part becomes ``%``) and the QoS in rmw_zenoh's compact form.
- Attachments of every sample: sequence number (int64 LE), source timestamp (ns since the
  epoch, int64 LE), GID length (one byte, 16) and the 16-byte GID; or, for releases up to 0.2.3,
  the same three values labelled with their names (``sequence_number`` …).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import Enum
from typing import Literal

import xxhash

from .types import dds_type_name, is_ros_type_name, ros_type_name

ADMIN_SPACE = "@ros2_lv"
GID_SIZE = 16
INFINITE = (9223372036, 854775807)
"""RMW_DURATION_INFINITE as (sec, nsec): rmw_zenoh's default deadline, lifespan and lease."""


class RmwZenohError(ValueError):
    """A name, token or attachment that does not follow the rmw_zenoh conventions."""


class EntityKind(Enum):
    """The kinds of graph entities, as written in liveliness tokens."""

    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


# ---------------------------------------------------------------------- names


def mangle(name: str) -> str:
    """A name as one key-expression chunk: every ``/`` becomes ``%``; an empty name is ``%``."""
    return name.replace("/", "%") if name else "%"


def demangle(chunk: str) -> str:
    """The name a mangled chunk stands for (``%`` alone is the empty name)."""
    return "" if chunk == "%" else chunk.replace("%", "/")


def fully_qualified_name(namespace: str, name: str) -> str:
    """``/ns/name`` from a namespace (``""`` or ``/`` for none) and a relative or absolute name."""
    if name.startswith("/"):
        return name
    namespace = namespace.strip("/")
    return f"/{namespace}/{name}" if namespace else f"/{name}"


def topic_keyexpr(domain_id: int, topic: str, type_name: str, type_hash: str) -> str:
    """The key expression a topic's samples are put on.

    Args:
        domain_id: ``ROS_DOMAIN_ID`` (0 by default).
        topic: the fully qualified topic name (``/robot1/chatter``).
        type_name: the ROS type (``std_msgs/msg/String``).
        type_hash: its RIHS01 hash (:meth:`runtime.ros.types.RosTypes.rihs01`).
    """
    _check_domain(domain_id)
    name = topic.strip("/")
    if not name or "//" in name or any(c in name for c in "*$?#"):
        raise RmwZenohError(f"{topic!r} is not a ROS 2 topic name")
    return f"{domain_id}/{name}/{dds_type_name(type_name)}/{type_hash}"


def _check_domain(domain_id: int) -> None:
    if isinstance(domain_id, bool) or not isinstance(domain_id, int) or domain_id < 0:
        raise RmwZenohError(f"a ROS domain id is a non-negative integer, got {domain_id!r}")


# ---------------------------------------------------------------------- QoS


@dataclass(frozen=True)
class RmwQos:
    """An rmw QoS profile with the rmw enum values (reliability 1 reliable / 2 best effort;
    durability 1 transient local / 2 volatile; history 1 keep last / 2 keep all; liveliness 1
    automatic / 3 manual by topic). Defaults are rmw_zenoh's defaults."""

    reliability: int = 1
    durability: int = 2
    history: int = 1
    depth: int = 42
    deadline: tuple[int, int] = INFINITE
    lifespan: tuple[int, int] = INFINITE
    liveliness: int = 1
    liveliness_lease_duration: tuple[int, int] = INFINITE

    @classmethod
    def of_topic(
        cls,
        reliability: str = "reliable",
        history: int = 1,
        deadline: float | None = None,
        lifespan: float | None = None,
    ) -> RmwQos:
        """The QoS of a CKM ``<Topic>``: its reliability, history depth, deadline and lifespan."""
        return cls(
            reliability=2 if reliability == "best-effort" else 1,
            depth=history,
            deadline=_duration(deadline),
            lifespan=_duration(lifespan),
        )


DEFAULT_QOS = RmwQos()


def _duration(seconds: float | None) -> tuple[int, int]:
    if seconds is None:
        return INFINITE
    total = round(seconds * 1e9)
    return total // 1_000_000_000, total % 1_000_000_000


def qos_to_keyexpr(qos: RmwQos) -> str:
    """rmw_zenoh's compact QoS text: ``rel:dur:hist,depth:dl_s,dl_ns:ls_s,ls_ns:liv,lease_s,lease_ns``
    where a value equal to rmw_zenoh's default is left empty (``::,10:,:,:,,`` is reliable,
    volatile, keep last 10)."""

    def part(value: int, default: int) -> str:
        return "" if value == default else str(value)

    d, lease = DEFAULT_QOS, qos.liveliness_lease_duration
    return (
        f"{part(qos.reliability, d.reliability)}:{part(qos.durability, d.durability)}:"
        f"{part(qos.history, d.history)},{part(qos.depth, d.depth)}:"
        f"{part(qos.deadline[0], d.deadline[0])},{part(qos.deadline[1], d.deadline[1])}:"
        f"{part(qos.lifespan[0], d.lifespan[0])},{part(qos.lifespan[1], d.lifespan[1])}:"
        f"{part(qos.liveliness, d.liveliness)},{part(lease[0], INFINITE[0])},{part(lease[1], INFINITE[1])}"
    )


def keyexpr_to_qos(text: str) -> RmwQos:
    """The QoS profile :func:`qos_to_keyexpr` wrote (empty parts take the defaults)."""
    parts = text.split(":")
    pieces = [p.split(",") for p in parts]
    if len(parts) != 6 or [len(p) for p in pieces] != [1, 1, 2, 2, 2, 3]:
        raise RmwZenohError(f"{text!r} is not an rmw_zenoh QoS string (rel:dur:hist,depth:s,ns:s,ns:liv,s,ns)")

    def num(value: str, default: int) -> int:
        if not value:
            return default
        if not value.isdigit():
            raise RmwZenohError(f"{text!r}: {value!r} is not a number")
        return int(value)

    d = DEFAULT_QOS
    (rel,), (dur,), (hist, depth), (dl_s, dl_ns), (ls_s, ls_ns), (liv, lease_s, lease_ns) = pieces
    return RmwQos(
        reliability=num(rel, d.reliability),
        durability=num(dur, d.durability),
        history=num(hist, d.history),
        depth=num(depth, d.depth),
        deadline=(num(dl_s, d.deadline[0]), num(dl_ns, d.deadline[1])),
        lifespan=(num(ls_s, d.lifespan[0]), num(ls_ns, d.lifespan[1])),
        liveliness=num(liv, d.liveliness),
        liveliness_lease_duration=(num(lease_s, INFINITE[0]), num(lease_ns, INFINITE[1])),
    )


# ---------------------------------------------------------------------- liveliness tokens


@dataclass(frozen=True)
class Endpoint:
    """A topic endpoint's part of a liveliness token."""

    topic: str
    type_name: str
    type_hash: str
    qos: RmwQos = DEFAULT_QOS


def liveliness_token(
    domain_id: int,
    session_id: str,
    node_id: int,
    entity_id: int,
    kind: EntityKind,
    node_name: str,
    *,
    namespace: str = "",
    enclave: str = "",
    endpoint: Endpoint | None = None,
) -> str:
    """The key expression of a node's (``kind`` NODE, ``entity_id`` = ``node_id``) or an endpoint's
    liveliness token.

    Args:
        session_id: the Zenoh session id in hex, as ``str(session.zid())`` gives it.
        endpoint: the topic, type, hash and QoS; required for every kind but NODE.
    """
    _check_domain(domain_id)
    if not session_id or any(c in session_id for c in "/*$?#"):
        raise RmwZenohError(f"{session_id!r} is not a Zenoh session id")
    parts = [
        ADMIN_SPACE,
        str(domain_id),
        session_id,
        str(node_id),
        str(entity_id),
        kind.value,
        mangle(enclave),
        mangle(namespace),
        mangle(node_name),
    ]
    if (kind == EntityKind.NODE) != (endpoint is None):
        raise RmwZenohError(f"a {kind.name.lower()} token {'takes no' if endpoint else 'needs an'} endpoint")
    if endpoint is not None:
        if not is_ros_type_name(endpoint.type_name):
            raise RmwZenohError(f"{endpoint.type_name!r} is not a ROS 2 type name")
        parts += [
            mangle(endpoint.topic),
            dds_type_name(endpoint.type_name),
            endpoint.type_hash,
            qos_to_keyexpr(endpoint.qos),
        ]
    return "/".join(parts)


@dataclass(frozen=True)
class ParsedToken:
    """What a liveliness token says about one entity of the ROS graph (for the Monitor view)."""

    domain_id: int
    session_id: str
    node_id: int
    entity_id: int
    kind: EntityKind
    enclave: str
    namespace: str
    node_name: str
    endpoint: Endpoint | None
    dds_type: str | None


def parse_liveliness_token(keyexpr: str) -> ParsedToken:
    """The entity a liveliness token announces; RmwZenohError if it is not one."""
    parts = keyexpr.split("/")
    if len(parts) not in (9, 13) or parts[0] != ADMIN_SPACE:
        raise RmwZenohError(f"{keyexpr!r} is not an rmw_zenoh liveliness token")
    try:
        kind = EntityKind(parts[5])
        domain, node_id, entity_id = int(parts[1]), int(parts[3]), int(parts[4])
    except ValueError as error:
        raise RmwZenohError(f"{keyexpr!r}: {error}") from error
    if (kind == EntityKind.NODE) != (len(parts) == 9):
        raise RmwZenohError(f"{keyexpr!r}: a {kind.name.lower()} token has the wrong number of parts")
    endpoint, dds = None, None
    if len(parts) == 13:
        dds = parts[10]
        endpoint = Endpoint(demangle(parts[9]), ros_type_name(dds), parts[11], keyexpr_to_qos(parts[12]))
    return ParsedToken(
        domain,
        parts[2],
        node_id,
        entity_id,
        kind,
        demangle(parts[6]),
        demangle(parts[7]),
        demangle(parts[8]),
        endpoint,
        dds,
    )


# ---------------------------------------------------------------------- GID and attachments


def entity_gid(token: str) -> bytes:
    """The 16-byte GID of the entity with liveliness token ``token``.

    rmw_zenoh hashes the token with XXH3-128 and stores the low then the high 64 bits, each
    little endian: the 128-bit digest as one little-endian integer.
    """
    return xxhash.xxh3_128_intdigest(token.encode("utf-8")).to_bytes(GID_SIZE, "little")


@dataclass(frozen=True)
class Attachment:
    """The metadata rmw_zenoh attaches to every sample, request and reply."""

    sequence_number: int
    source_timestamp: int  # ns since the UNIX epoch
    source_gid: bytes

    def __post_init__(self) -> None:
        if len(self.source_gid) != GID_SIZE:
            raise RmwZenohError(f"a GID has {GID_SIZE} bytes, got {len(self.source_gid)}")
        for name in ("sequence_number", "source_timestamp"):
            if not -(2**63) <= getattr(self, name) < 2**63:
                raise RmwZenohError(f"{name} {getattr(self, name)} does not fit an int64")


AttachmentFormat = Literal["compact", "labelled"]
_LABELS = (b"sequence_number", b"source_timestamp", b"source_gid")


def encode_attachment(attachment: Attachment, form: AttachmentFormat = "compact") -> bytes:
    """The attachment bytes: ``compact`` (33 bytes, current releases) or ``labelled`` (each value
    after its name, as a length-prefixed string; releases up to 0.2.3)."""
    seq = struct.pack("<q", attachment.sequence_number)
    stamp = struct.pack("<q", attachment.source_timestamp)
    gid = bytes([GID_SIZE]) + attachment.source_gid
    if form == "compact":
        return seq + stamp + gid
    if form == "labelled":
        seq_label, stamp_label, gid_label = (bytes([len(label)]) + label for label in _LABELS)
        return seq_label + seq + stamp_label + stamp + gid_label + gid
    raise RmwZenohError(f"unknown attachment format {form!r} (compact, labelled)")


def decode_attachment(data: bytes) -> Attachment:
    """The attachment in ``data``, in either format."""
    if len(data) == 33 and data[16] == GID_SIZE:
        seq, stamp = struct.unpack_from("<qq", data)
        return Attachment(seq, stamp, bytes(data[17:]))
    values: dict[bytes, bytes] = {}
    at = 0
    try:
        while at < len(data):
            label = data[at + 1 : at + 1 + data[at]]
            at += 1 + data[at]
            if label == b"source_gid":
                size = data[at]
                values[label], at = data[at + 1 : at + 1 + size], at + 1 + size
            else:
                values[label], at = data[at : at + 8], at + 8
    except IndexError:
        raise RmwZenohError(f"{len(data)}-byte attachment is truncated") from None
    if set(values) != set(_LABELS) or len(values[b"sequence_number"]) != 8 or len(values[b"source_timestamp"]) != 8:
        raise RmwZenohError(f"{data.hex()} is neither a 33-byte nor a labelled rmw_zenoh attachment")
    (seq,) = struct.unpack("<q", values[b"sequence_number"])
    (stamp,) = struct.unpack("<q", values[b"source_timestamp"])
    return Attachment(seq, stamp, values[b"source_gid"])
