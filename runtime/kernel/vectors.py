"""What a sensor of a vector channel publishes: the whole read, shaped by its topic's type (decision D99).

A sensor is *vector* when its channel has ``size`` > 1 or its backend's ``value_type(channel)``
says it reads arrays (``runtime.verification.manifest.ARRAY``). Its read is published whole:

- on a numeric built-in topic (``float64``, ``uint16``, …): a numpy array of that dtype;
- on a ``bytes`` topic: the numpy array (float64) as read — the codec carries arrays;
- on a MessageType topic with a *vector field* (the first field of ``count="0"`` whose type is a
  number, or of type ``bytes``): a dict of every field — ``time`` fields get the sample's stamp,
  the vector field the read (an array of the field's dtype, or for ``bytes`` one byte per element),
  a field named like one of the channel's Params that Param's value (an Image's ``width`` and
  ``height``), any other single string field the channel's ``units`` (an Image's ``encoding``:
  ``rgb8``), every other field its type's zero;
- on a MessageType of exactly ``size`` scalar numeric fields: a dict of them in declaration order;
- on a ROS 2 type (``sensor_msgs/msg/LaserScan``, ``std_msgs/msg/Float64MultiArray``): the message,
  its first array of numbers holding the read (:mod:`runtime.ros.sensors`, decision D193).

:func:`vector_field`, :func:`shape_of` and :func:`problem` are shared with ``verify``, which accepts
exactly these and refuses the others with the kernel's sentence (:func:`refusal`) at ``<Sensor topic>``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from ckmconf.model import BUILTIN_TYPES, HWChannel, MessageType, Sensor
from ckmconf.model.kernel import Field
from ckmconf.rostypes import is_ros_type

from ..verification.manifest import NUMBER

if TYPE_CHECKING:  # rosbags' store is loaded only for a sensor on a ROS type
    from ..ros.config import ConfigRosTypes
    from ..ros.types import RosTypes

NUMERIC = frozenset(BUILTIN_TYPES - {"string", "bytes"})
DTYPES: dict[str, Any] = {
    "bool": np.bool_, "int8": np.int8, "int16": np.int16, "int32": np.int32, "int64": np.int64,
    "uint8": np.uint8, "uint16": np.uint16, "uint32": np.uint32, "uint64": np.uint64,
    "float32": np.float32, "float64": np.float64, "time": np.float64,
}
Shaper = Callable[[Any, float], Any]
"""(raw read, stamp) → the value published."""


def vector_field(message: MessageType) -> Field | None:
    """The field of ``message`` a vector read fills: the first variable-length number array or bytes field."""
    for field in message.fields:
        if field.type == "bytes" or (field.count == 0 and field.type in NUMERIC):
            return field
    return None


def _scalar_fields(message: MessageType) -> bool:
    return all(f.count == 1 and f.type in NUMERIC for f in message.fields)


def shape_of(carried: str, size: int, types: Mapping[str, MessageType]) -> str | None:
    """How a vector read of ``size`` elements travels on a topic of type ``carried``; None if it cannot.

    Returns ``"array"`` (numeric or bytes topic), ``"field:NAME"`` (a MessageType's vector field) or
    ``"fields"`` (a MessageType of exactly ``size`` scalar numbers).
    """
    if carried in NUMERIC or carried == "bytes":
        return "array"
    message = types.get(carried)
    if message is None:
        return None
    field = vector_field(message)
    if field is not None:
        return f"field:{field.name}"
    if _scalar_fields(message) and len(message.fields) == size:
        return "fields"
    return None


def _zero(field: Field, types: Mapping[str, MessageType]) -> Any:
    if field.type in types:
        one: Any = {f.name: _zero(f, types) for f in types[field.type].fields}
        return one if field.count == 1 else [one] * field.count
    if field.type == "string":
        return "" if field.count == 1 else [""] * field.count
    if field.type == "bytes":
        return b""
    if field.count == 1:
        return DTYPES[field.type](0).item()
    return np.zeros(field.count, dtype=DTYPES[field.type])


def _converted(text: str, field: Field) -> Any:
    if field.type == "string":
        return text
    if field.type == "bool":
        return text.strip().lower() in ("1", "true", "yes")
    return DTYPES[field.type](float(text)).item()


def _bytes(values: np.ndarray[Any, Any], owner: str) -> bytes:
    if values.size and (values.min() < 0 or values.max() > 255):
        raise ValueError(f"{owner}: a bytes field takes one byte per element, but the read holds values outside 0-255")
    return values.astype(np.uint8).tobytes()


def problem(
    carried: str, channel: HWChannel, types: Mapping[str, MessageType], ros: Callable[[], RosTypes]
) -> str | None:
    """Why a topic of type ``carried`` cannot carry whole reads of ``channel``, a clause following the
    type's name; None when it can, or when the type is unknown (the topic's own problem). ``ros``
    gives the ROS type store."""
    if is_ros_type(carried):
        from ..ros.sensors import vector_refusal  # rosbags' store: only for sensors on ROS types

        return vector_refusal(ros(), carried, channel)
    if carried not in BUILTIN_TYPES and carried not in types:
        return None
    if shape_of(carried, channel.size, types) is None:
        return ('which has no field to carry them: a numeric or bytes topic, a MessageType with a count="0" '
                f"number field or a bytes field, or one of {channel.size} scalar numbers")
    return None


def refusal(sensor: Sensor, channel: HWChannel, carried: str, why: str) -> str:
    """The one sentence the kernel (at set-up) and ``verify`` give at the ``topic`` of a ``<Sensor>``
    whose topic cannot carry its whole reads (``why``: :func:`problem`'s clause)."""
    kind = "ROS type" if is_ros_type(carried) else "type"
    return (f"sensor {sensor.name!r} writes whole reads of channel {channel.name!r} (size {channel.size}) "
            f"onto topic {sensor.topic!r} of {kind} {carried}, {why}")


def scalar_refusals(sensor: Sensor, channel: HWChannel, carried: str, ros: Callable[[], ConfigRosTypes]) -> list[str]:
    """Why the single numbers a scalar sensor publishes cannot travel on its topic of ROS type
    ``carried`` (a type with no numeric ``data`` field, D131): the sentences ``verify`` and the
    kernel give at ``<Sensor topic>``; none for a CKM type (``verify``'s type rules apply)."""
    if not is_ros_type(carried):
        return []
    return [
        f"sensor {sensor.name!r} writes single numbers (channel {channel.name!r}, size {channel.size}) "
        f"onto topic {sensor.topic!r} of ROS type {carried}: {problem}"
        for problem in ros().value_problems(NUMBER, carried)
    ]


def shaper(
    sensor: Sensor,
    carried: str,
    channel: HWChannel,
    types: Mapping[str, MessageType],
    ros: Callable[[], RosTypes],
) -> Shaper:
    """The function turning a vector read of ``sensor`` into what it publishes on a topic of type ``carried``.

    Raises:
        ValueError: the topic's type cannot carry the read: :func:`refusal`'s sentence.
    """
    owner = f"sensor {sensor.name!r}"
    why = problem(carried, channel, types, ros)
    if why is None and is_ros_type(carried):
        from ..ros.sensors import ros_shaper

        try:
            return ros_shaper(ros(), carried, channel, sensor.period, owner)
        except ValueError as exc:  # unknown type, a Param that does not convert to its field
            why = str(exc)
    shape = shape_of(carried, channel.size, types)
    if why is not None or shape is None:
        raise ValueError(refusal(sensor, channel, carried, why or "which cannot carry them"))
    if shape == "array":
        dtype = DTYPES.get(carried, np.float64)
        return lambda raw, stamp: np.asarray(raw, dtype=dtype)
    message = types[carried]
    if shape == "fields":
        names = [f.name for f in message.fields]
        return lambda raw, stamp: dict(zip(names, (float(x) for x in raw), strict=True))
    target = vector_field(message)
    assert target is not None
    params = {p.name: p.value for p in channel.params}
    fixed = {f.name: _zero(f, types) for f in message.fields if f.type != "time" and f is not target}
    for f in message.fields:
        if f.name in params and f.count == 1 and f is not target:
            fixed[f.name] = _converted(params[f.name], f)
        elif f.type == "string" and f.count == 1 and f.name in fixed:
            fixed[f.name] = channel.units or ""  # an Image's encoding: the channel's units (rgb8)
    stamps = [f.name for f in message.fields if f.type == "time" and f is not target]

    def build(raw: Any, stamp: float) -> dict[str, Any]:
        values = np.asarray(raw, dtype=np.float64)
        data = _bytes(values, owner) if target.type == "bytes" else values.astype(DTYPES[target.type])
        out = dict(fixed)
        out.update(dict.fromkeys(stamps, stamp))
        out[target.name] = data
        return {f.name: out[f.name] for f in message.fields}

    return build


def is_vector(channel: HWChannel, backend_class: type) -> bool:
    """Whether a sensor of ``channel`` publishes whole reads: size > 1, or a backend typing its reads as arrays."""
    typed = getattr(backend_class, "value_type", None)
    return channel.size > 1 or (callable(typed) and typed(channel) == "array")


def chain_refusal(channel: HWChannel, backend_class: type | None) -> str | None:
    """Why an adaptation chain cannot apply to a vector sensor of ``channel``, or None if it can.

    A chain adapts numbers one at a time, so on a vector it runs once per element with its own
    state (a bus of joint positions); a frame or a scan (a ``stream`` channel, or reads typed as
    arrays) is not a set of calibrated numbers and is refused.
    """
    typed = getattr(backend_class, "value_type", None)
    if channel.kind == "stream" or (callable(typed) and typed(channel) == "array"):
        return (f"an adaptation chain applies to numbers one at a time, not to the frames or scans of "
                f"{channel.kind} channel {channel.name!r} (size {channel.size}); adapt them in a processing service")
    return None
