"""CKMultiPeer frames (§3.1.4.3, Fig. 3.6): prologue, header and load, optionally authenticated.

Wire layout (big-endian)::

    prologue  magic "CK" | version u8 | type u8 | flags u8 | reserved u8 | length u32
    body      msgpack array [header..., load]                       (length bytes)
    auth      sequence u64 | HMAC-SHA256 (32 bytes)                  (only when flags & AUTH)

``length`` counts the body only. The MAC covers the link's session id, the direction, the
sequence number, the prologue and the body, so a frame cannot be replayed, reordered,
reflected back to its sender or moved to another link. Payloads are msgpack: never pickle.
"""

from __future__ import annotations

import enum
import hashlib
import hmac
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import msgpack

MAGIC = b"CK"
VERSION = 1
PROLOGUE = struct.Struct("!2sBBBxI")
AUTH = struct.Struct("!Q")
MAC_SIZE = 32
FLAG_AUTH = 0x01


class FrameType(enum.IntEnum):
    """Message types. HELLO opens a link; the others are the thesis's five (Fig. 3.6)."""

    HELLO = 0
    PLAIN = 1
    TOPICDATA = 2
    TOPICLINKS = 3
    SYNCTIME = 4
    PROXYWRAPPER = 5


class FrameError(ValueError):
    """A frame that must close the link: malformed, truncated, oversized, unknown or forged."""


@dataclass(frozen=True)
class Frame:
    """A decoded frame (a message type of §3.1.4.3): its type and msgpack body (a list: header fields then the load)."""

    type: FrameType
    body: list[Any]
    sequence: int = 0


class Authenticator:
    """HMAC-SHA256 with per-direction sequence numbers for one link (or one discovery channel)."""

    def __init__(self, key: bytes, session: bytes = b"") -> None:
        self._key = key
        self.session = session
        self._sent = 0
        self._seen = 0
        self.rejected = 0

    def rekey(self, session: bytes) -> None:
        """Bind to a link's session id (both sides' nonces); sequence numbers restart."""
        self.session = session
        self._sent = 0
        self._seen = 0

    def seal(self, direction: bytes, head: bytes, body: bytes) -> bytes:
        """Trailer for an outgoing frame: next sequence number and HMAC over direction, head and body."""
        self._sent += 1
        sequence = AUTH.pack(self._sent)
        return sequence + self._mac(direction, sequence, head, body)

    def check(self, direction: bytes, head: bytes, body: bytes, trailer: bytes) -> int:
        """Verify a frame's trailer; returns its sequence number.

        Args:
            direction: Which side sent the frame (part of the MAC, so a frame cannot be reflected).
            head: The frame's prologue bytes.
            body: The frame's msgpack body.
            trailer: Sequence number and MAC as received.

        Raises:
            FrameError: Bad MAC (wrong key, tampering) or a sequence number not above the last seen.
        """
        sequence, mac = trailer[: AUTH.size], trailer[AUTH.size :]
        if not hmac.compare_digest(mac, self._mac(direction, sequence, head, body)):
            self.rejected += 1
            raise FrameError("bad MAC (wrong group key or tampered frame)")
        number: int = AUTH.unpack(sequence)[0]
        if number <= self._seen:
            self.rejected += 1
            raise FrameError(f"replayed frame (sequence {number} after {self._seen})")
        self._seen = number
        return number

    def _mac(self, direction: bytes, sequence: bytes, head: bytes, body: bytes) -> bytes:
        message = b"".join((self.session, direction, sequence, head, body))
        return hmac.new(self._key, message, hashlib.sha256).digest()


def encode(kind: FrameType, body: list[Any], *, auth: Authenticator | None = None, direction: bytes = b">") -> bytes:
    """One frame as bytes."""
    payload: bytes = msgpack.packb(body, use_bin_type=True)
    flags = FLAG_AUTH if auth is not None else 0
    head = PROLOGUE.pack(MAGIC, VERSION, int(kind), flags, len(payload))
    if auth is None:
        return head + payload
    return head + payload + auth.seal(direction, head, payload)


class Decoder:
    """Incremental frame decoder for one byte stream, bounded by ``max_frame``.

    Feed it whatever ``recv`` returned; iterate the complete frames. Any violation raises
    FrameError, after which the stream is unusable and the link must be closed.
    """

    def __init__(self, max_frame: int, *, auth: Authenticator | None = None, direction: bytes = b"<") -> None:
        self.max_frame = max_frame
        self.auth = auth
        self.direction = direction
        self._buffer = bytearray()

    def feed(self, data: bytes) -> Iterator[Frame]:
        """Append received bytes and yield every frame now complete; FrameError on a violation."""
        self._buffer += data
        while True:
            frame = self._next()
            if frame is None:
                return
            yield frame

    def pending(self) -> int:
        """Bytes buffered towards the next, incomplete frame."""
        return len(self._buffer)

    def _next(self) -> Frame | None:
        buffer = self._buffer
        if len(buffer) < PROLOGUE.size:
            if buffer[: len(MAGIC)] and not MAGIC.startswith(bytes(buffer[: len(MAGIC)])):
                raise FrameError("bad magic (not a CKMultiPeer frame)")
            return None
        magic, version, kind, flags, length = PROLOGUE.unpack_from(buffer)
        if magic != MAGIC:
            raise FrameError("bad magic (not a CKMultiPeer frame)")
        if version != VERSION:
            raise FrameError(f"unsupported frame version {version}")
        if length > self.max_frame:
            raise FrameError(f"frame of {length} bytes exceeds the {self.max_frame}-byte limit")
        try:
            frame_type = FrameType(kind)
        except ValueError:
            raise FrameError(f"unknown frame type {kind}") from None
        authenticated = bool(flags & FLAG_AUTH)
        if flags & ~FLAG_AUTH:
            raise FrameError(f"unknown frame flags {flags:#x}")
        if self.auth is not None and not authenticated:
            raise FrameError("unauthenticated frame on a keyed link")
        if self.auth is None and authenticated:
            raise FrameError("authenticated frame but this peer has no group key")
        trailer = AUTH.size + MAC_SIZE if authenticated else 0
        total = PROLOGUE.size + length + trailer
        if len(buffer) < total:
            return None
        head = bytes(buffer[: PROLOGUE.size])
        payload = bytes(buffer[PROLOGUE.size : PROLOGUE.size + length])
        sequence = 0
        if self.auth is not None:
            sequence = self.auth.check(self.direction, head, payload, bytes(buffer[PROLOGUE.size + length : total]))
        del buffer[:total]
        return Frame(frame_type, unpack_body(payload, self.max_frame), sequence)


def unpack_body(payload: bytes, limit: int) -> list[Any]:
    """A frame body: a msgpack array, with container sizes bounded so a small frame cannot explode."""
    try:
        body = msgpack.unpackb(
            payload,
            raw=False,
            strict_map_key=True,
            max_bin_len=limit,
            max_str_len=limit,
            max_array_len=min(limit, 1_000_000),
            max_map_len=min(limit, 1_000_000),
            max_ext_len=0,
        )
    except (ValueError, msgpack.UnpackException, TypeError, OverflowError, RecursionError) as exc:
        raise FrameError(f"malformed frame body: {type(exc).__name__}") from None
    if not isinstance(body, list):
        raise FrameError("malformed frame body: not an array")
    return body
