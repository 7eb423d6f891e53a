"""A safe msgpack-able encoding of numpy arrays and the nested values that hold them.

Plugin inputs, results and states cross the network when a processing plugin is delegated
(§3.1.2.5–6). Pickle would run code on the receiver, so values are rebuilt from plain data only:
arrays become their dtype name, shape and raw bytes, and the receiver checks everything before it
allocates — a dtype from a short whitelist (numbers and booleans: no objects, no records), a
shape of non-negative integers, ``prod(shape) × itemsize == len(bytes)``, and a cap on the bytes,
the nesting depth and the number of items of one value. Any violation is a ``CodecError`` (a
ValueError) saying what was wrong; nothing else escapes ``decode``.

Tagged values are one-key dicts whose key starts with ``~``::

    {"~nd": [dtype, shape, bytes]}   numpy array (little-endian, C order)
    {"~sc": [dtype, bytes]}          numpy scalar (np.float32(1.5) stays an np.float32)
    {"~tu": [items]}                 tuple (msgpack has only arrays: tuples would come back as lists)
    {"~map": [[key, value], ...]}    dict with non-str keys, or a one-key dict whose key starts with ~

Everything else passes through: None, bool, int (64-bit), float, str, bytes, lists and str-keyed
dicts. Encoding then decoding gives an equal value of the same types (arrays come back writable).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

MAX_BYTES = 16 * 1024 * 1024  # the CKMultiPeer frame limit: a bigger value could not travel anyway
MAX_DEPTH = 64
MAX_ITEMS = 1_000_000
MAX_NDIM = 32

DTYPES = frozenset(["|b1", "|i1", "|u1", "<i2", "<u2", "<i4", "<u4", "<i8", "<u8", "<f2", "<f4", "<f8", "<c8", "<c16"])
"""Accepted dtypes, as little-endian ``dtype.str``: plain numbers and booleans."""

_ARRAY, _SCALAR, _TUPLE, _MAP = "~nd", "~sc", "~tu", "~map"


class CodecError(ValueError):
    """A value that cannot be encoded, or encoded data that must not be decoded."""


@dataclass
class _Budget:
    """What one encode or decode may still spend, so a small message cannot explode."""

    max_bytes: int
    max_depth: int
    items: int
    used: int = 0

    def spend(self, nbytes: int, what: str) -> None:
        self.used += nbytes
        if self.used > self.max_bytes:
            raise CodecError(f"{what} takes the value over the {self.max_bytes}-byte limit")

    def count(self, depth: int) -> None:
        if depth > self.max_depth:
            raise CodecError(f"the value is nested deeper than {self.max_depth} levels")
        self.items -= 1
        if self.items < 0:
            raise CodecError("the value has too many items")


def encode(value: Any, *, max_bytes: int = MAX_BYTES, max_depth: int = MAX_DEPTH, max_items: int = MAX_ITEMS) -> Any:
    """``value`` as msgpack-able plain data; CodecError for anything else (objects, big or odd arrays)."""
    return _encode(value, _Budget(max_bytes, max_depth, max_items), 0)


def decode(value: Any, *, max_bytes: int = MAX_BYTES, max_depth: int = MAX_DEPTH, max_items: int = MAX_ITEMS) -> Any:
    """The value ``encode`` was given, rebuilt and checked; CodecError on anything malformed or too big."""
    return _decode(value, _Budget(max_bytes, max_depth, max_items), 0)


# ---------------------------------------------------------------------- encoding


def _dtype_code(dtype: np.dtype[Any]) -> str:
    code = dtype.newbyteorder("<").str if dtype.kind in "biufc" and dtype.fields is None else dtype.str
    if code not in DTYPES:
        raise CodecError(f"dtype {dtype.str!r} is not allowed (allowed: {', '.join(sorted(DTYPES))})")
    return code


def _encode(value: Any, budget: _Budget, depth: int) -> Any:
    budget.count(depth)
    # numpy before the Python scalars: np.float64 is a float subclass and must stay an np.float64.
    if isinstance(value, np.ndarray):
        code = _dtype_code(value.dtype)
        if value.ndim > MAX_NDIM:
            raise CodecError(f"an array of {value.ndim} dimensions exceeds the limit of {MAX_NDIM}")
        budget.spend(value.nbytes, f"an array of {value.nbytes} bytes")
        raw = np.ascontiguousarray(value, dtype=np.dtype(code)).tobytes()
        return {_ARRAY: [code, list(value.shape), raw]}
    if isinstance(value, np.generic):
        if isinstance(value, np.str_ | np.bytes_):
            return _encode(value.item(), budget, depth)
        code = _dtype_code(value.dtype)
        return {_SCALAR: [code, np.asarray(value, dtype=np.dtype(code)).tobytes()]}
    if value is None or isinstance(value, bool | float | str):
        if isinstance(value, str):
            budget.spend(len(value), "a string")
        return value
    if isinstance(value, int):
        if not -(2**63) <= value < 2**64:
            raise CodecError(f"the integer {value} does not fit in 64 bits")
        return value
    if isinstance(value, bytes | bytearray | memoryview):
        raw = bytes(value)
        budget.spend(len(raw), f"{len(raw)} raw bytes")
        return raw
    if isinstance(value, list):
        return [_encode(item, budget, depth + 1) for item in value]
    if isinstance(value, tuple):
        return {_TUPLE: [_encode(item, budget, depth + 1) for item in value]}
    if isinstance(value, dict):
        plain = all(isinstance(k, str) for k in value) and not (len(value) == 1 and next(iter(value)).startswith("~"))
        if plain:
            return {k: _encode(v, budget, depth + 1) for k, v in value.items()}
        return {_MAP: [[_encode(k, budget, depth + 1), _encode(v, budget, depth + 1)] for k, v in value.items()]}
    raise CodecError(f"cannot encode a value of type {type(value).__name__}")


# ---------------------------------------------------------------------- decoding


def _dtype(code: Any) -> np.dtype[Any]:
    if not isinstance(code, str) or code not in DTYPES:
        raise CodecError(f"dtype {code!r} is not allowed (allowed: {', '.join(sorted(DTYPES))})")
    return np.dtype(code)


def _pair(payload: Any, tag: str, size: int) -> list[Any]:
    if not isinstance(payload, list | tuple) or len(payload) != size:
        raise CodecError(f"{tag} must hold a list of {size} items")
    return list(payload)


def _array(payload: Any, budget: _Budget) -> np.ndarray[Any, Any]:
    code, shape, raw = _pair(payload, _ARRAY, 3)
    dtype = _dtype(code)
    if not isinstance(shape, list | tuple) or len(shape) > MAX_NDIM:
        raise CodecError(f"an array shape must be a list of at most {MAX_NDIM} sizes, got {shape!r:.80}")
    if not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape):
        raise CodecError(f"an array shape must hold non-negative integers, got {shape!r:.80}")
    if not isinstance(raw, bytes):
        raise CodecError(f"array data must be bytes, got {type(raw).__name__}")
    nbytes = math.prod(shape) * dtype.itemsize  # Python ints: a hostile shape cannot overflow
    if nbytes != len(raw):
        raise CodecError(f"an array of shape {tuple(shape)} and dtype {code} needs {nbytes} bytes, got {len(raw)}")
    budget.spend(nbytes, f"an array of {nbytes} bytes")
    array: np.ndarray[Any, Any] = np.frombuffer(raw, dtype=dtype).reshape(shape).copy()  # writable, owns its data
    return array


def _decode(value: Any, budget: _Budget, depth: int) -> Any:
    budget.count(depth)
    if value is None or isinstance(value, bool | int | float):
        return value
    if isinstance(value, str | bytes):
        budget.spend(len(value), "a string")
        return value
    if isinstance(value, list):
        return [_decode(item, budget, depth + 1) for item in value]
    if not isinstance(value, dict):
        raise CodecError(f"cannot decode a value of type {type(value).__name__}")
    if len(value) == 1:
        tag, payload = next(iter(value.items()))
        if isinstance(tag, str) and tag.startswith("~"):
            return _tagged(tag, payload, budget, depth)
    if not all(isinstance(k, str) for k in value):
        raise CodecError("a plain dict must have str keys")
    return {k: _decode(v, budget, depth + 1) for k, v in value.items()}


def _tagged(tag: str, payload: Any, budget: _Budget, depth: int) -> Any:
    if tag == _ARRAY:
        return _array(payload, budget)
    if tag == _SCALAR:
        code, raw = _pair(payload, _SCALAR, 2)
        dtype = _dtype(code)
        if not isinstance(raw, bytes) or len(raw) != dtype.itemsize:
            raise CodecError(f"a {code} scalar needs {dtype.itemsize} bytes")
        return np.frombuffer(raw, dtype=dtype)[0]
    if tag == _TUPLE:
        if not isinstance(payload, list):
            raise CodecError(f"{_TUPLE} must hold a list")
        return tuple(_decode(item, budget, depth + 1) for item in payload)
    if tag == _MAP:
        if not isinstance(payload, list):
            raise CodecError(f"{_MAP} must hold a list of [key, value] pairs")
        result: dict[Any, Any] = {}
        for pair in payload:
            key, item = _pair(pair, f"an entry of {_MAP}", 2)
            key, item = _decode(key, budget, depth + 1), _decode(item, budget, depth + 1)
            try:
                result[key] = item
            except TypeError:  # an unhashable key (a list, a dict)
                raise CodecError(f"a {type(key).__name__} cannot be a dict key") from None
        return result
    raise CodecError(f"unknown tag {tag!r:.40}")
