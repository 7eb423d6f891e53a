"""``hardware.bag``: an input HWChannel played back from a recorded rosbag2 bag (issue L point 2).

A recorded bag stands in for a simulated or real device: give the channel ``backend="bag"`` and
the sensor that samples it publishes what was recorded, in the recorded order and spacing, as the
device did (thesis §4.4.1; decision D156). Any rosbag2 bag ``rosbags`` reads will do: MCAP or
sqlite3, written by ``ckm-run --record`` or by ``ros2 bag record``.

Params. ``bag`` is the bag directory (the one holding ``metadata.yaml``), relative to the
configuration file; ``topic`` the bag topic the channel plays (``/motor_node/speed``: the bag's
names, see ``ros2 bag info`` or ``BagSource.topic_types``); ``type`` optionally the ROS 2 type the
topic must have; ``field`` the dotted path of the value inside each message (default: ``data``
when the type has it, the pixels of a ``sensor_msgs/msg/Image``); ``rate`` the playback speed;
``loop`` whether to start again after the last message (else the last value is held);
``start`` seconds of the bag's beginning to skip.

What a read gives: a number field is one value (channel ``size`` 1); an array, a sequence or an
image is ``size`` values, flattened row-major, as ``hardware.sim`` gives its lidars and cameras.

Time. Playback runs on the channel's scope clock (:mod:`plugins.hardware.simulation`: the node's
clock under ``ckm-run``, a :class:`ManualClock` in tests) from the channel's first read: a read at
``t`` seconds after it gives the last message recorded at most ``start + t × rate`` seconds after
the bag's first message of the topic, so the recorded time offsets are kept (scaled by ``rate``).
A looping bag's period is its span plus one mean message interval, so the spacing stays regular.

Errors. A missing bag, a topic the bag lacks, a type other than ``type``, a field the type lacks
or that holds no numbers, and a size that does not match the channel's are found when the node is
built, before it runs, and reported as ``FILE:LINE:COL`` at the Param (:class:`ConfigError`).
Messages are kept as their CDR bytes and decoded when first played, through
:mod:`runtime.ros.convert`.
"""

from __future__ import annotations

import bisect
import math
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype

from ckmconf.errors import MEMORY_FILE, ConfigError
from ckmconf.model import HWChannel, Param
from ckmconf.source import Limits, read_source
from runtime.kernel.interfaces import Backend, ParamError, Value, read_params
from runtime.ros.bag import BagError, BagSource
from runtime.ros.convert import IMAGE, decode_payload
from runtime.ros.types import RosTypeError, RosTypes
from runtime.verification.manifest import NUMBERS, REQUIRED, P, Params, Ports

from .simulation import Clock, PlantScope, scope_for

_SPEC = Params(
    P("bag", REQUIRED, "rosbag2 bag directory (MCAP or sqlite3), relative to the configuration file.", type=str),
    P("topic", REQUIRED, "Topic of the bag the channel plays, as the bag names it (/motor_node/speed).", type=str),
    P("type", "", "ROS 2 type the topic must have in the bag (default: whichever it has)."),
    P("field", "", "Dotted path of the value in each message (default: data, or an Image's pixels)."),
    P("rate", 1.0, "Playback speed: 2 plays twice as fast as recorded.", above=0.0),
    P("loop", False, "Play the bag again from its first message after the last (else hold the last value)."),
    P("start", 0.0, "Seconds of the bag's beginning to skip.", unit="s", min=0.0),
)
_NUMERIC = frozenset(
    [
        "bool",
        "byte",
        "char",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "float32",
        "float64",
    ]
)


class BagBackend(Backend):
    """An input channel played back from one topic of a rosbag2 bag (see the module docstring)."""

    PARAMS = _SPEC
    PORTS = Ports(outputs={"*": NUMBERS})

    def __init__(self, channel: HWChannel, *, scope: PlantScope | None = None) -> None:
        super().__init__(channel)
        self.owner = f"bag channel {channel.name!r}"
        self.values = read_params(channel.params, _SPEC, owner=self.owner)
        if channel.direction != "in":
            raise ParamError(f"{self.owner}: a bag plays recorded values: it serves input channels only")
        here = Path(channel.loc.file) if channel.loc and channel.loc.file != "<memory>" else None
        self.path = ((here.parent if here else Path.cwd()) / self.values["bag"]).resolve()
        self.clock: Clock = (scope if scope is not None else scope_for(channel)).clock
        self.types = RosTypes()
        self.type_name = ""
        self.field: tuple[str, ...] = ()
        self.times: list[float] = []  # seconds from the topic's first message
        self.data: list[bytes] = []  # CDR bytes, decoded when played
        self.period = 0.0  # a looping bag's period
        self._origin: float | None = None  # clock time of the first read
        self._cached: tuple[int, Value] | None = None

    # ------------------------------------------------------------------ set-up: every check

    def setup(self) -> None:
        """Read the topic's messages (as CDR bytes) and check type, field and size against the channel."""
        values = self.values
        if not (self.path / "metadata.yaml").is_file():
            what = "does not exist" if not self.path.exists() else "is not a rosbag2 bag (no metadata.yaml)"
            raise self._error("bag", f"{self.owner}: the bag {self.path} {what}")
        source = BagSource(self.path, types=self.types)
        try:
            topics = source.topic_types()
        except Exception as error:  # rosbags' reader errors: a damaged or unsupported bag
            raise self._error("bag", f"{self.owner}: cannot read the bag {self.path}: {error}") from None
        topic = values["topic"]
        if topic not in topics:
            listed = ", ".join(f"{t} ({k})" for t, k in sorted(topics.items())) or "none"
            raise self._error("topic", f"{self.owner}: the bag {self.path} has no topic {topic!r} (topics: {listed})")
        self.type_name = topics[topic]
        if values["type"] and values["type"] != self.type_name:
            raise self._error(
                "type",
                f"{self.owner}: topic {topic} of the bag {self.path} is a {self.type_name}, not a {values['type']}",
            )
        source.topics = frozenset({topic})
        stamps: list[int] = []
        try:
            for _, _, stamp, data in source.records():
                stamps.append(stamp)
                self.data.append(data)
        except (BagError, RosTypeError) as error:
            raise self._error("bag", f"{self.owner}: {error}") from None
        if not self.data:
            raise self._error("topic", f"{self.owner}: topic {topic} of the bag {self.path} has no message")
        self.times = [(stamp - stamps[0]) * 1e-9 for stamp in stamps]  # integer ns first: no epoch rounding
        span = self.times[-1]
        if values["start"] >= span > 0 or (span == 0 and values["start"] > 0):
            raise self._error("start", f"{self.owner}: start {values['start']:g} s is past the topic's {span:g} s")
        self.period = span + (span / (len(self.times) - 1) if len(self.times) > 1 else 1.0)
        self.field = self._field_path()
        self._check_size(0)

    def _field_path(self) -> tuple[str, ...]:
        """The field the channel reads, checked against the type: numbers, arrays of numbers or an image."""
        given = self.values["field"]
        if not given:
            if self.type_name == IMAGE:
                return ()
            if "data" not in dict(self.types.fields(self.type_name)):
                raise self._error(
                    "field" if any(p.name == "field" for p in self.channel.params) else "topic",
                    f"{self.owner}: {self.type_name} has no 'data' field: name the one to read with Param 'field' "
                    f"({', '.join(name for name, _ in self.types.fields(self.type_name))})",
                )
            given = "data"
        path = tuple(given.split("."))
        type_name = self.type_name
        for index, name in enumerate(path):
            fields = dict(self.types.fields(type_name))
            if name not in fields:
                raise self._error(
                    "field", f"{self.owner}: field {given!r}: {type_name} has no field {name!r} ({', '.join(fields)})"
                )
            kind, detail = fields[name]
            last = index == len(path) - 1
            if kind == Nodetype.NAME:
                type_name = detail
                if last and type_name != IMAGE:
                    raise self._error("field", f"{self.owner}: field {given!r} is a {type_name} message, not numbers")
                continue
            element = detail[0] if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) else (kind, detail)
            if not last or element[0] != Nodetype.BASE or element[1][0] not in _NUMERIC:
                raise self._error(
                    "field", f"{self.owner}: field {given!r} of {self.type_name} holds no numbers to read"
                )
        return path

    def _check_size(self, index: int) -> None:
        value = self._decode(index)
        count = 1 if isinstance(value, float) else len(value)
        if count != self.channel.size:
            raise self._error(
                "field" if self.values["field"] else "topic",
                f"{self.owner}: the channel's size is {self.channel.size}, but message {index} of "
                f"{self.values['topic']} gives {count} value(s) ({self.type_name}"
                f"{'.' + '.'.join(self.field) if self.field else ''})",
            )

    # ------------------------------------------------------------------ playback

    def position(self) -> int:
        """The index of the message playing now (the clock starts the playback at the first call)."""
        now = self.clock()
        if self._origin is None:
            self._origin = now
        offset = self.values["start"] + (now - self._origin) * self.values["rate"]
        if self.values["loop"] and offset >= self.period:
            offset = math.fmod(offset, self.period)
        # half a nanosecond of slack: a clock read as float seconds must not miss a message due now
        return max(bisect.bisect_right(self.times, offset + 0.5e-9) - 1, 0)

    def read(self) -> Value:
        """The value of the message playing now: one number, or ``size`` numbers flattened row-major.

        Raises:
            ValueError: the message gives another number of values than the ``<HWChannel>``'s ``size``.
        """
        if not self.data:
            raise RuntimeError(f"{self.owner} is used before setup() or after stop()")
        index = self.position()
        if self._cached is None or self._cached[0] != index:
            value = self._decode(index)
            size = 1 if isinstance(value, float) else len(value)
            if size != self.channel.size:  # a sequence that changed length in the bag
                raise ValueError(
                    f"{self.owner}: message {index} gives {size} values, the channel takes {self.channel.size}"
                )
            self._cached = (index, value)
        return self._cached[1]

    def write(self, value: Value) -> None:
        """Always a RuntimeError: a bag only plays back, so a ``direction="in"`` ``<HWChannel>`` is served."""
        raise RuntimeError(f"{self.owner} is an input channel")

    def stop(self) -> None:
        """Drop the messages read at setup; the channel can no longer be read."""
        self.data, self.times, self._cached = [], [], None

    # ------------------------------------------------------------------ internals

    def _decode(self, index: int) -> Value:
        payload: Any = decode_payload(self.types, self.type_name, self.data[index])
        for name in self.field:
            payload = payload[name]
        if isinstance(payload, bytes):
            payload = np.frombuffer(payload, dtype=np.uint8)
        if isinstance(payload, np.ndarray):
            return tuple(payload.astype(np.float64).ravel().tolist())
        return float(payload)

    def _error(self, param: str, message: str) -> ConfigError:
        """The problem at the value of the Param that causes it (as ``verify`` places it), else at the channel."""
        record: Param | HWChannel = next((p for p in self.channel.params if p.name == param), self.channel)
        if not isinstance(record, Param):
            return ConfigError.of(record, message)
        if record.loc is not None and record.loc.file != MEMORY_FILE:
            try:
                return ConfigError.at(read_source(record.loc.file, Limits()).attr_loc_at(record.loc, "value"), message)
            except ConfigError:  # the file changed or went since it was loaded: the element will do
                pass
        return ConfigError.of(record, message, "value")
