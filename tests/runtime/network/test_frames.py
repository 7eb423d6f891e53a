"""CKMultiPeer frames (§3.1.4.3): round trips, every kind of malformed input, authentication.

The decoder is the first thing hostile bytes meet, so its contract is strict: whatever it is
fed, in whatever pieces, it yields Frames or raises FrameError — never anything else.
"""

from __future__ import annotations

import itertools
import os
import struct
from typing import Any

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from runtime.network.frames import (
    AUTH,
    FLAG_AUTH,
    MAC_SIZE,
    MAGIC,
    PROLOGUE,
    VERSION,
    Authenticator,
    Decoder,
    Frame,
    FrameError,
    FrameType,
    encode,
)

KEY = b"0123456789abcdef0123456789abcdef"
SESSION = os.urandom(32)
LIMIT = 4096


def decode_all(decoder: Decoder, chunks: list[bytes]) -> list[Frame]:
    frames: list[Frame] = []
    for chunk in chunks:
        frames.extend(decoder.feed(chunk))
    return frames


def raw_frame(payload: bytes, *, magic: bytes = MAGIC, version: int = VERSION, kind: int = 1, flags: int = 0) -> bytes:
    """A frame built by hand, so any prologue field can be wrong."""
    return PROLOGUE.pack(magic, version, kind, flags, len(payload)) + payload


def keyed_pair(session: bytes = SESSION) -> tuple[Authenticator, Decoder]:
    """A sender's authenticator and the receiving decoder of the same link direction (L → H)."""
    return Authenticator(KEY, session), Decoder(LIMIT, auth=Authenticator(KEY, session), direction=b"L")


BODIES: list[list[Any]] = [
    [],
    [None, True, False, 0, -1, 2**63 - 1, -(2**63), 2**64 - 1],
    [1.5, -0.0, "text", "ünïcødé", b"\x00\xff bytes"],
    ["/topic", 7, 1700000000.123, {"x": [1, 2, {"y": b"z"}], "n": None}],
    [[[[[]]]], {}],
]


# ---------------------------------------------------------------------- round trips


@pytest.mark.parametrize("kind", list(FrameType))
@pytest.mark.parametrize("body", BODIES)
def test_every_frame_type_round_trips(kind: FrameType, body: list[Any]) -> None:
    data = encode(kind, body)
    [frame] = Decoder(LIMIT).feed(data)
    assert (frame.type, frame.body) == (kind, body)


@pytest.mark.parametrize("kind", list(FrameType))
def test_authenticated_frames_round_trip_with_increasing_sequence_numbers(kind: FrameType) -> None:
    sender, decoder = keyed_pair()
    stream = b"".join(encode(kind, [i, "x" * i], auth=sender, direction=b"L") for i in range(5))
    frames = decode_all(decoder, [stream[i : i + 7] for i in range(0, len(stream), 7)])  # in small pieces
    assert [(f.type, f.body, f.sequence) for f in frames] == [(kind, [i, "x" * i], i + 1) for i in range(5)]
    assert decoder.pending() == 0


def test_a_stream_of_frames_fed_one_byte_at_a_time() -> None:
    stream = b"".join(encode(kind, body) for kind in FrameType for body in BODIES)
    frames = decode_all(Decoder(LIMIT), [bytes([b]) for b in stream])
    assert [(f.type, f.body) for f in frames] == [(kind, body) for kind in FrameType for body in BODIES]


def test_a_frame_of_exactly_max_frame_bytes_is_accepted() -> None:
    payload = msgpack.packb([b"x" * (LIMIT - 4)], use_bin_type=True)
    assert len(payload) == LIMIT
    [frame] = Decoder(LIMIT).feed(raw_frame(payload))
    assert frame.body == [b"x" * (LIMIT - 4)]


# ---------------------------------------------------------------------- malformed frames


def nested(depth: int) -> bytes:
    return b"\x91" * depth + b"\xc0"


HOSTILE: dict[str, tuple[bytes, str]] = {
    "oversized": (PROLOGUE.pack(MAGIC, VERSION, 1, 0, LIMIT + 1), "exceeds"),
    "oversized-max-u32": (PROLOGUE.pack(MAGIC, VERSION, 1, 0, 0xFFFFFFFF), "exceeds"),
    "bad-magic": (raw_frame(msgpack.packb([1]), magic=b"XX"), "magic"),
    "bad-magic-early": (b"G", "magic"),
    "http-request": (b"GET / HTTP/1.1\r\nHost: x\r\n\r\n", "magic"),
    "bad-version-0": (raw_frame(msgpack.packb([1]), version=0), "version"),
    "bad-version-2": (raw_frame(msgpack.packb([1]), version=2), "version"),
    "unknown-type": (raw_frame(msgpack.packb([1]), kind=6), "unknown frame type"),
    "unknown-type-255": (raw_frame(msgpack.packb([1]), kind=255), "unknown frame type"),
    "unknown-flags": (raw_frame(msgpack.packb([1]), flags=0x02), "flags"),
    "unknown-flags-with-auth": (raw_frame(msgpack.packb([1]), flags=0x81), "flags"),
    "auth-flag-without-key": (raw_frame(msgpack.packb([1]), flags=FLAG_AUTH) + bytes(AUTH.size + MAC_SIZE), "key"),
    "garbage-msgpack": (raw_frame(b"\xc1"), "malformed"),
    "truncated-body": (raw_frame(msgpack.packb(["abcdef"])[:-2]), "malformed"),
    "empty-body": (raw_frame(b""), "malformed"),
    "extra-bytes-after-body": (raw_frame(msgpack.packb([1]) + b"\x00"), "malformed"),
    "map-body": (raw_frame(msgpack.packb({"a": 1})), "not an array"),
    "int-body": (raw_frame(msgpack.packb(7)), "not an array"),
    "string-body": (raw_frame(msgpack.packb("text")), "not an array"),
    "nil-body": (raw_frame(b"\xc0"), "not an array"),
    "deeply-nested": (raw_frame(nested(LIMIT - 1)), "malformed"),
    "array-claiming-4g-items": (raw_frame(b"\xdd\xff\xff\xff\xff"), "malformed"),
    "str-claiming-4g-bytes": (raw_frame(b"\x91\xdb\xff\xff\xff\xff"), "malformed"),
    "ext-type": (raw_frame(b"\x91\xd4\x01\x00"), "malformed"),
    "timestamp-ext": (raw_frame(b"\x91" + msgpack.packb(msgpack.Timestamp(1, 0))), "malformed"),
    "int-map-key": (raw_frame(b"\x91\x81\x01\x02"), "malformed"),
    "list-map-key": (raw_frame(b"\x91\x81\x90\x02"), "malformed"),
    "invalid-utf8": (raw_frame(b"\x91\xa2\xff\xfe"), "malformed"),
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_malformed_frames_raise_frame_error(name: str) -> None:
    data, reason = HOSTILE[name]
    with pytest.raises(FrameError, match=reason):
        decode_all(Decoder(LIMIT), [data])


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_malformed_frames_raise_frame_error_after_valid_ones_and_in_pieces(name: str) -> None:
    data, reason = HOSTILE[name]
    decoder = Decoder(LIMIT)
    assert len(list(decoder.feed(encode(FrameType.PLAIN, ["ok"])))) == 1
    with pytest.raises(FrameError, match=reason):
        decode_all(decoder, [data[i : i + 3] for i in range(0, len(data), 3)])


def test_a_truncated_frame_yields_nothing_and_waits_for_the_rest() -> None:
    data = encode(FrameType.TOPICDATA, ["/t", 1, 1.0, b"x" * 100])
    for cut in range(len(data)):
        decoder = Decoder(LIMIT)
        assert list(decoder.feed(data[:cut])) == []
        assert decoder.pending() == cut
        [frame] = decoder.feed(data[cut:])
        assert frame.body == ["/t", 1, 1.0, b"x" * 100]


def test_an_unauthenticated_frame_on_a_keyed_decoder_is_rejected() -> None:
    _, decoder = keyed_pair()
    with pytest.raises(FrameError, match="unauthenticated"):
        decode_all(decoder, [encode(FrameType.PLAIN, ["hi"])])


# ---------------------------------------------------------------------- authentication


def test_every_tampered_byte_is_rejected() -> None:
    sender, _ = keyed_pair()
    data = encode(FrameType.TOPICDATA, ["/t", 1, 2.5, b"payload"], auth=sender, direction=b"L")
    for position in range(len(data)):
        for flip in (0x01, 0x80):
            tampered = bytearray(data)
            tampered[position] ^= flip
            _, decoder = keyed_pair()
            try:
                frames = decode_all(decoder, [bytes(tampered)])
            except FrameError:
                continue
            # A longer length field only makes the decoder wait for bytes that never come.
            assert frames == [], f"byte {position} ^ {flip:#x} was accepted"
            assert position in range(6, 10), f"byte {position} ^ {flip:#x} neither rejected nor pending"


def test_a_replayed_frame_is_rejected_and_counted() -> None:
    sender, decoder = keyed_pair()
    data = encode(FrameType.PLAIN, ["once"], auth=sender, direction=b"L")
    assert len(decode_all(decoder, [data])) == 1
    with pytest.raises(FrameError, match="replayed"):
        decode_all(decoder, [data])
    assert decoder.auth is not None and decoder.auth.rejected == 1


def test_reordered_frames_are_rejected() -> None:
    sender, decoder = keyed_pair()
    first = encode(FrameType.PLAIN, [1], auth=sender, direction=b"L")
    second = encode(FrameType.PLAIN, [2], auth=sender, direction=b"L")
    assert decode_all(decoder, [second])[0].body == [2]
    with pytest.raises(FrameError, match="replayed"):
        decode_all(decoder, [first])


def test_a_frame_moved_to_the_other_direction_is_rejected() -> None:
    sender = Authenticator(KEY, SESSION)
    data = encode(FrameType.PLAIN, ["to H"], auth=sender, direction=b"L")
    reflected = Decoder(LIMIT, auth=Authenticator(KEY, SESSION), direction=b"H")  # the sender's own receive side
    with pytest.raises(FrameError, match="MAC"):
        decode_all(reflected, [data])


def test_a_frame_moved_to_another_link_is_rejected() -> None:
    sender, _ = keyed_pair(session=b"session one")
    _, other_link = keyed_pair(session=b"session two")
    with pytest.raises(FrameError, match="MAC"):
        decode_all(other_link, [encode(FrameType.PLAIN, ["x"], auth=sender, direction=b"L")])


def test_a_frame_sealed_with_another_key_is_rejected() -> None:
    stranger = Authenticator(b"another key of enough length!!!!", SESSION)
    _, decoder = keyed_pair()
    with pytest.raises(FrameError, match="MAC"):
        decode_all(decoder, [encode(FrameType.PLAIN, ["x"], auth=stranger, direction=b"L")])


def test_a_rekeyed_link_rejects_frames_of_the_hello_session() -> None:
    sender, decoder = keyed_pair(session=b"ckm-hello")
    assert decoder.auth is not None
    first = encode(FrameType.HELLO, [1], auth=sender, direction=b"L")
    assert len(decode_all(decoder, [first])) == 1
    decoder.auth.rekey(SESSION)
    with pytest.raises(FrameError, match="MAC"):
        decode_all(decoder, [encode(FrameType.PLAIN, [2], auth=sender, direction=b"L")])


def test_a_truncated_mac_waits_and_a_zeroed_mac_is_rejected() -> None:
    sender, decoder = keyed_pair()
    data = encode(FrameType.PLAIN, ["x"], auth=sender, direction=b"L")
    assert list(decoder.feed(data[:-1])) == []
    _, decoder = keyed_pair()
    forged = data[: -MAC_SIZE - AUTH.size] + struct.pack("!Q", 1) + bytes(MAC_SIZE)
    with pytest.raises(FrameError, match="MAC"):
        decode_all(decoder, [forged])


# ---------------------------------------------------------------------- property tests

leaves = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**63), max_value=2**64 - 1)
    | st.floats(allow_nan=False)
    | st.text(max_size=16)
    | st.binary(max_size=16)
)
values = st.recursive(
    leaves,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=12,
)
bodies = st.lists(values, max_size=5)
kinds = st.sampled_from(list(FrameType))


def split(data: bytes, draw: st.DataObject) -> list[bytes]:
    cuts = sorted(draw.draw(st.lists(st.integers(0, len(data)), max_size=6), label="cuts"))
    edges = [0, *cuts, len(data)]
    return [data[a:b] for a, b in itertools.pairwise(edges)]


def only_frames_or_frame_error(decoder: Decoder, chunks: list[bytes]) -> list[Frame]:
    """The contract under test: Frames out, or FrameError; any other exception fails the test."""
    try:
        frames = decode_all(decoder, chunks)
    except FrameError:
        return []
    assert all(isinstance(f, Frame) and isinstance(f.body, list) for f in frames)
    return frames


@settings(max_examples=300, deadline=None)
@given(kind=kinds, body=bodies, data=st.data())
def test_property_any_body_round_trips_in_any_pieces(kind: FrameType, body: list[Any], data: st.DataObject) -> None:
    stream = encode(kind, body)
    frames = decode_all(Decoder(1 << 20), split(stream, data))
    assert [(f.type, f.body) for f in frames] == [(kind, body)]


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(blob=st.binary(max_size=600), keyed=st.booleans(), data=st.data())
def test_property_random_bytes_give_frames_or_frame_error(blob: bytes, keyed: bool, data: st.DataObject) -> None:
    decoder = keyed_pair()[1] if keyed else Decoder(LIMIT)
    only_frames_or_frame_error(decoder, split(blob, data))


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    frames=st.lists(st.tuples(kinds, bodies), min_size=1, max_size=4),
    keyed=st.booleans(),
    mutations=st.lists(
        st.tuples(
            st.sampled_from(["flip", "set", "insert", "delete", "truncate"]), st.floats(0, 1), st.integers(0, 255)
        ),
        min_size=1,
        max_size=6,
    ),
    data=st.data(),
)
def test_property_mutated_valid_frames_give_frames_or_frame_error(
    frames: list[tuple[FrameType, list[Any]]],
    keyed: bool,
    mutations: list[tuple[str, float, int]],
    data: st.DataObject,
) -> None:
    sender, decoder = keyed_pair() if keyed else (None, Decoder(1 << 16))
    stream = bytearray(b"".join(encode(kind, body, auth=sender, direction=b"L") for kind, body in frames))
    for operation, where, byte in mutations:
        at = min(int(where * len(stream)), max(len(stream) - 1, 0))
        if not stream:
            break
        if operation == "flip":
            stream[at] ^= byte or 1
        elif operation == "set":
            stream[at] = byte
        elif operation == "insert":
            stream[at:at] = bytes([byte])
        elif operation == "delete":
            del stream[at]
        else:
            del stream[at:]
    decoded = only_frames_or_frame_error(decoder, split(bytes(stream), data))
    if keyed:  # whatever survives a mutation of an authenticated stream is an untouched original frame
        originals = [(kind, body) for kind, body in frames]
        assert all((f.type, f.body) in originals for f in decoded)
