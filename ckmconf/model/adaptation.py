"""Records of the adaptation chain of a sensor or actuator (schemas/kernel.xsd ``<Adaptation>``, §3.1.2.1, §3.1.2.3).

The steps convert raw channel values to engineering units (sensors) or back (actuators), applied
in document order; :mod:`runtime.kernel.adaptation` runs them.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..binding import Record, attr, children
from .params import Param


@dataclass(frozen=True, kw_only=True)
class Linear(Record):
    """<Linear>: y = gain * x + offset."""

    TAG = "Linear"
    gain: float = attr(default=1.0)
    offset: float = attr(default=0.0)


@dataclass(frozen=True, kw_only=True)
class Polynomial(Record):
    """<Polynomial>: y = c0 + c1 x + c2 x² + …"""

    TAG = "Polynomial"
    coefficients: tuple[float, ...] = attr()


@dataclass(frozen=True, kw_only=True)
class LowPass(Record):
    """<LowPass>: first-order low-pass filter, cut-off in Hz."""

    TAG = "LowPass"
    cutoff: float = attr()


@dataclass(frozen=True, kw_only=True)
class MovingAverage(Record):
    """<MovingAverage>: mean of the last window samples."""

    TAG = "MovingAverage"
    window: int = attr()


@dataclass(frozen=True, kw_only=True)
class Median(Record):
    """<Median>: median of the last window samples."""

    TAG = "Median"
    window: int = attr()


@dataclass(frozen=True, kw_only=True)
class Clamp(Record):
    """<Clamp>: limit to [min, max]."""

    TAG = "Clamp"
    min: float = attr()
    max: float = attr()


@dataclass(frozen=True, kw_only=True)
class Deadband(Record):
    """<Deadband>: values within ±width of zero become zero."""

    TAG = "Deadband"
    width: float = attr()


@dataclass(frozen=True, kw_only=True)
class Point(Record):
    """<Point>: one x, y pair of a lookup table."""

    TAG = "Point"
    x: float = attr()
    y: float = attr()


@dataclass(frozen=True, kw_only=True)
class Lookup(Record):
    """<Lookup>: piece-wise linear table."""

    TAG = "Lookup"
    points: tuple[Point, ...] = children()


@dataclass(frozen=True, kw_only=True)
class Function(Record):
    """<Function>: a registered processing-function plugin."""

    TAG = "Function"
    plugin: str = attr()
    params: tuple[Param, ...] = children()


AdaptationStep = Linear | Polynomial | LowPass | MovingAverage | Median | Clamp | Deadband | Lookup | Function


@dataclass(frozen=True, kw_only=True)
class Adaptation(Record):
    """<Adaptation>: functions applied in order (raw→engineering for sensors, inverse for actuators)."""

    TAG = "Adaptation"
    steps: tuple[AdaptationStep, ...] = children()
