"""rmw_zenoh conventions, byte-exact against the samples of rmw_zenoh's docs/design.md (issue L point 3).

The expected strings below are copied from the design document of ros2/rmw_zenoh (sections "Topic
and Service name mapping to Zenoh key expressions", "Graph Cache" and "Publishers"); the 33-byte
and labelled attachments are cross-checked with eclipse-zenoh's own serializer (``zenoh.ext``).
"""

from __future__ import annotations

import pytest
from zenoh.ext import Int64, UInt8, z_serialize

from runtime.ros.rmw_zenoh import (
    DEFAULT_QOS,
    Attachment,
    Endpoint,
    EntityKind,
    RmwQos,
    RmwZenohError,
    decode_attachment,
    demangle,
    encode_attachment,
    entity_gid,
    fully_qualified_name,
    keyexpr_to_qos,
    liveliness_token,
    mangle,
    parse_liveliness_token,
    qos_to_keyexpr,
    topic_keyexpr,
)
from runtime.ros.types import RosTypes

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
LISTENER_SESSION = "aac3178e146ba6f1fc6e6a4085e77f21"
TALKER_SESSION = "8b20917502ee955ac4476e0266340d5c"


@pytest.fixture(scope="module")
def string_hash() -> str:
    return RosTypes().rihs01("std_msgs/msg/String")


def test_topic_key_expressions_of_the_design_document(string_hash: str) -> None:
    assert string_hash == STRING_HASH
    assert topic_keyexpr(0, "/chatter", "std_msgs/msg/String", string_hash) == (
        "0/chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    )
    assert topic_keyexpr(0, fully_qualified_name("/robot1", "chatter"), "std_msgs/msg/String", string_hash) == (
        "0/robot1/chatter/std_msgs::msg::dds_::String_/"
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    )


def test_liveliness_tokens_of_the_design_document(string_hash: str) -> None:
    assert liveliness_token(2, LISTENER_SESSION, 0, 0, EntityKind.NODE, "listener") == (
        "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
    )
    subscription = Endpoint("/chatter", "std_msgs/msg/String", string_hash, RmwQos(depth=10))
    assert liveliness_token(2, LISTENER_SESSION, 0, 10, EntityKind.SUBSCRIPTION, "listener", endpoint=subscription) == (
        "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/"
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,10:,:,:,,"
    )
    publisher = Endpoint("/chatter", "std_msgs/msg/String", string_hash, RmwQos(depth=7))
    assert liveliness_token(2, TALKER_SESSION, 0, 10, EntityKind.PUBLISHER, "talker", endpoint=publisher) == (
        "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/"
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,7:,:,:,,"
    )


def test_tokens_with_namespace_and_enclave_mangle_every_slash(string_hash: str) -> None:
    endpoint = Endpoint("/robot1/camera/image", "sensor_msgs/msg/Image", "RIHS01_ab", RmwQos.of_topic("best-effort", 1))
    token = liveliness_token(
        0, "1f", 3, 4, EntityKind.PUBLISHER, "cam", namespace="/robot1", enclave="/ckm", endpoint=endpoint
    )
    assert token == (
        "@ros2_lv/0/1f/3/4/MP/%ckm/%robot1/cam/%robot1%camera%image/sensor_msgs::msg::dds_::Image_/"
        "RIHS01_ab/2::,1:,:,:,,"
    )
    parsed = parse_liveliness_token(token)
    assert (parsed.kind, parsed.namespace, parsed.enclave, parsed.node_name) == (
        EntityKind.PUBLISHER,
        "/robot1",
        "/ckm",
        "cam",
    )
    assert parsed.endpoint == endpoint and parsed.dds_type == "sensor_msgs::msg::dds_::Image_"
    node = parse_liveliness_token("@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener")
    assert (node.domain_id, node.session_id, node.kind, node.namespace, node.endpoint) == (
        2,
        LISTENER_SESSION,
        EntityKind.NODE,
        "",
        None,
    )


def test_mangling() -> None:
    assert [mangle(n) for n in ("", "/", "/chatter", "/a/b")] == ["%", "%", "%chatter", "%a%b"]
    assert [demangle(c) for c in ("%", "%chatter", "%a%b")] == ["", "/chatter", "/a/b"]
    assert fully_qualified_name("", "chatter") == "/chatter" and fully_qualified_name("/ns/", "/abs") == "/abs"


def test_qos_strings() -> None:
    assert qos_to_keyexpr(DEFAULT_QOS) == "::,:,:,:,,"
    assert qos_to_keyexpr(RmwQos(depth=10)) == "::,10:,:,:,,"
    custom = RmwQos(
        reliability=2,
        durability=1,
        history=2,
        depth=5,
        deadline=(0, 200_000_000),
        lifespan=(1, 500_000_000),
        liveliness=3,
        liveliness_lease_duration=(2, 0),
    )
    text = qos_to_keyexpr(custom)
    assert text == "2:1:2,5:0,200000000:1,500000000:3,2,0"
    assert keyexpr_to_qos(text) == custom and keyexpr_to_qos("::,10:,:,:,,") == RmwQos(depth=10)
    assert RmwQos.of_topic("reliable", 3, deadline=0.25, lifespan=None) == RmwQos(depth=3, deadline=(0, 250_000_000))
    with pytest.raises(RmwZenohError, match="is not an rmw_zenoh QoS string"):
        keyexpr_to_qos("1:2:3")
    with pytest.raises(RmwZenohError, match="'x' is not a number"):
        keyexpr_to_qos("x::,:,:,:,,")


def test_the_compact_attachment_is_33_bytes_as_the_design_document_lays_out() -> None:
    gid = bytes(range(16))
    stamp = 0x0102030405060708  # ns since the epoch; its little-endian bytes are easy to read
    data = encode_attachment(Attachment(5, stamp, gid))
    assert data == bytes.fromhex(
        "0500000000000000"  # sequence number, int64 little endian
        "0807060504030201"  # source timestamp, int64 little endian
        "10"  # GID length (16)
        "000102030405060708090a0b0c0d0e0f"
    )  # the GID
    assert len(data) == 33
    assert decode_attachment(data) == Attachment(5, stamp, gid)


def test_both_attachment_formats_match_zenohs_own_serializer() -> None:
    gid = bytes.fromhex("76148a538308fe55a6c5375462ca1de6")
    attachment = Attachment(-3, 42, gid)
    compact = z_serialize((Int64(-3), Int64(42), [UInt8(b) for b in gid])).to_bytes()
    assert encode_attachment(attachment, "compact") == compact
    labelled = z_serialize(
        ("sequence_number", Int64(-3), "source_timestamp", Int64(42), "source_gid", [UInt8(b) for b in gid])
    ).to_bytes()
    assert encode_attachment(attachment, "labelled") == labelled and len(labelled) == 77
    assert decode_attachment(labelled) == attachment


def test_bad_attachments_are_refused() -> None:
    with pytest.raises(RmwZenohError, match="a GID has 16 bytes, got 3"):
        Attachment(1, 2, b"abc")
    with pytest.raises(RmwZenohError, match="does not fit an int64"):
        Attachment(2**63, 0, bytes(16))
    with pytest.raises(RmwZenohError, match="neither a 33-byte nor a labelled"):
        decode_attachment(b"\x01\x02")
    with pytest.raises(RmwZenohError, match="unknown attachment format 'json'"):
        encode_attachment(Attachment(1, 2, bytes(16)), "json")  # type: ignore[arg-type]


def test_the_gid_is_the_xxh3_128_of_the_token_low_half_first() -> None:
    # XXH3-128 of the empty input is 99aa06d3014798d8 6001c324468d497f (high, low): the xxHash test vector.
    assert entity_gid("") == bytes.fromhex("7f498d4624c30160d8984701d306aa99")
    token = "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
    assert entity_gid(token) == entity_gid(token) != entity_gid(token + "2")


def test_bad_names_and_tokens_are_refused(string_hash: str) -> None:
    with pytest.raises(RmwZenohError, match="a ROS domain id is a non-negative integer"):
        topic_keyexpr(-1, "/chatter", "std_msgs/msg/String", string_hash)
    with pytest.raises(RmwZenohError, match="is not a ROS 2 topic name"):
        topic_keyexpr(0, "/a/*", "std_msgs/msg/String", string_hash)
    with pytest.raises(RmwZenohError, match="a publisher token needs an endpoint"):
        liveliness_token(0, "1f", 0, 1, EntityKind.PUBLISHER, "n")
    with pytest.raises(RmwZenohError, match="a node token takes no endpoint"):
        liveliness_token(0, "1f", 0, 0, EntityKind.NODE, "n", endpoint=Endpoint("/t", "std_msgs/msg/String", "h"))
    with pytest.raises(RmwZenohError, match="is not a Zenoh session id"):
        liveliness_token(0, "a/b", 0, 0, EntityKind.NODE, "n")
    with pytest.raises(RmwZenohError, match="is not an rmw_zenoh liveliness token"):
        parse_liveliness_token("0/chatter/std_msgs::msg::dds_::String_/" + string_hash)
    with pytest.raises(RmwZenohError, match="wrong number of parts"):
        parse_liveliness_token("@ros2_lv/0/1f/0/0/MP/%/%/talker")
