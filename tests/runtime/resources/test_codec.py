"""The delegation codec: numpy arrays and nested values round-trip through msgpack; hostile data is refused."""

from __future__ import annotations

from typing import Any

import msgpack
import numpy as np
import pytest

from runtime.network.frames import unpack_body
from runtime.resources.codec import CodecError, decode, encode
from tests.runtime.resources.plugin_host_peer import same


def _wire(value: Any) -> Any:
    """``value`` encoded, sent through msgpack as CKMultiPeer does, and decoded."""
    packed = msgpack.packb([encode(value)], use_bin_type=True)
    return decode(unpack_body(packed, 1 << 24)[0])


DTYPES = ["bool", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64"]
DTYPES += ["float16", "float32", "float64", "complex64", "complex128"]


@pytest.mark.parametrize("dtype", DTYPES)
def test_arrays_of_every_allowed_dtype_round_trip(dtype: str) -> None:
    array = (np.arange(24) % 7).astype(dtype).reshape(2, 3, 4)
    back = _wire(array)
    assert same(back, array)
    assert back.flags.writeable and back.flags.owndata


def test_odd_layouts_round_trip_as_c_ordered_native_arrays() -> None:
    base = np.arange(60, dtype=np.float64).reshape(6, 10)
    for array in (base[::2, 1::3], np.asfortranarray(base), base.astype(">f4"), np.zeros((0, 3), np.uint8)):
        back = _wire(array)
        assert back.shape == array.shape and np.array_equal(back, array)
    assert same(_wire(np.array(3.5)), np.array(3.5))  # 0-d array stays an array
    assert _wire(base.astype(">i4")).dtype == np.dtype("<i4")


def test_nested_values_keep_their_types() -> None:
    value = {
        "mean": np.ones((2, 2), np.float32),
        "count": 3,
        "pair": ("a", np.int64(7)),
        "scalars": [np.float32(1.5), np.bool_(True), np.uint8(255), 2.5, None, True, b"raw", "text"],
        "by_id": {1: "one", (2, 3): [np.zeros(2)]},
        "~tricky": 1,
        "nested": [{"~nd": "not an array"}],
    }
    back = _wire(value)
    assert same(back, value)
    assert type(back["scalars"][0]) is np.float32
    assert back["nested"] == [{"~nd": "not an array"}]  # a user's ~-key dict is escaped, not decoded


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (object(), "cannot encode a value of type object"),
        (np.array([object()]), "dtype '|O' is not allowed"),
        (np.array(["text"]), "dtype '<U4' is not allowed"),
        (np.zeros(2, dtype=[("x", "f4")]), "is not allowed"),
        (np.datetime64("2020-01-01"), "dtype '<M8[D]' is not allowed"),
        ({1, 2}, "cannot encode a value of type set"),
        (2**64, "does not fit in 64 bits"),
        (np.zeros(1000, np.uint8), "over the 100-byte limit"),
    ],
)
def test_values_that_cannot_travel_are_refused_on_encoding(value: Any, message: str) -> None:
    with pytest.raises(CodecError, match=message.replace("[", r"\[").replace("]", r"\]").replace("|", r"\|")):
        encode(value, max_bytes=100)


def test_self_referencing_values_are_refused_not_recursed_forever() -> None:
    loop: list[Any] = []
    loop.append(loop)
    with pytest.raises(CodecError, match="nested deeper than 64 levels"):
        encode(loop)


HOSTILE: list[tuple[Any, str]] = [
    ({"~nd": ["|O", [1], b"x" * 8]}, "dtype '|O' is not allowed"),
    ({"~nd": [">f8", [1], b"x" * 8]}, "dtype '>f8' is not allowed"),
    ({"~nd": [5, [1], b"x"]}, "dtype 5 is not allowed"),
    ({"~nd": ["<f8", [10**9, 10**9], b"x" * 8]}, r"needs 8000000000000000000 bytes, got 8"),
    ({"~nd": ["<f8", [2], b"x" * 8]}, r"needs 16 bytes, got 8"),
    ({"~nd": ["<f8", [-1], b""]}, "non-negative integers"),
    ({"~nd": ["<f8", [True], b"x" * 8]}, "non-negative integers"),
    ({"~nd": ["<f8", [1.0], b"x" * 8]}, "non-negative integers"),
    ({"~nd": ["<f8", "1", b"x" * 8]}, "shape must be a list"),
    ({"~nd": ["<f8", [1] * 40, b"x" * 8]}, "at most 32 sizes"),
    ({"~nd": ["<f8", [1], "x" * 8]}, "array data must be bytes, got str"),
    ({"~nd": ["<f8", [1]]}, "must hold a list of 3 items"),
    ({"~nd": None}, "must hold a list of 3 items"),
    ({"~nd": ["|u1", [200], b"x" * 200]}, "over the 100-byte limit"),
    ([{"~nd": ["|u1", [60], b"x" * 60]}] * 2, "over the 100-byte limit"),
    ({"~sc": ["<f8", b"x"]}, "needs 8 bytes"),
    ({"~tu": "abc"}, "must hold a list"),
    ({"~map": [[[1, 2], "unhashable"]]}, "a list cannot be a dict key"),
    ({"~map": [[1]]}, "must hold a list of 2 items"),
    ({"~exec": "os.system('x')"}, "unknown tag '~exec'"),
    ({1: "int key"}, "must have str keys"),
    (object(), "cannot decode a value of type object"),
]


@pytest.mark.parametrize(("value", "message"), HOSTILE)
def test_hostile_data_is_refused_with_a_clear_reason(value: Any, message: str) -> None:
    with pytest.raises(CodecError, match=message):
        decode(value, max_bytes=100)


def test_depth_and_item_counts_are_capped() -> None:
    deep: Any = 0
    for _ in range(100):
        deep = [deep]
    with pytest.raises(CodecError, match="nested deeper than 64 levels"):
        decode(deep)
    with pytest.raises(CodecError, match="too many items"):
        decode(list(range(1000)), max_items=100)
    assert decode(list(range(99)), max_items=100) == list(range(99))
