"""``hardware.sine``: a signal generator standing in for a sensor (the hardware-backend example).

An input channel reads ``offset + amplitude·sin(2π·frequency·t)``, t in seconds since ``setup()``;
an output channel keeps the last value written (read it back to check what was driven).
"""

from __future__ import annotations

import math
import time
from typing import ClassVar

from ckmconf.model import HWChannel
from runtime.kernel.interfaces import Backend, Value, read_params
from runtime.verification.manifest import NUMBER, P, Params, Ports


class SineBackend(Backend):
    """A sine-wave generator on one-value channels."""

    PARAMS: ClassVar[Params] = Params(
        P("amplitude", 1.0, "Peak deviation from the offset.", unit="channel units", min=0.0),
        P("frequency", 1.0, "Frequency of the wave.", unit="Hz", above=0.0),
        P("offset", 0.0, "Value around which the wave oscillates.", unit="channel units"),
    )
    PORTS: ClassVar[Ports] = Ports(outputs={"*": NUMBER}, sizes=(1,))

    def __init__(self, channel: HWChannel) -> None:
        super().__init__(channel)  # no I/O here: only read and check the Params
        values = read_params(channel.params, self.PARAMS, owner=f"sine channel {channel.name!r}")
        self.amplitude: float = values["amplitude"]
        self.frequency: float = values["frequency"]
        self.offset: float = values["offset"]
        self.start: float | None = None
        self.last = 0.0

    def setup(self) -> None:
        """Start the wave's clock (the first I/O of a backend belongs here, not in ``__init__``)."""
        self.start = time.monotonic()

    def read(self) -> Value:
        """The wave's value now (kernel.xsd ``HWChannel``), or the last value written on an output channel.

        Raises:
            RuntimeError: an input channel is read before ``setup()``.
        """
        if self.channel.direction == "out":
            return self.last
        if self.start is None:
            raise RuntimeError(f"sine channel {self.channel.name!r} is read before setup()")
        elapsed = time.monotonic() - self.start
        return self.offset + self.amplitude * math.sin(2.0 * math.pi * self.frequency * elapsed)

    def write(self, value: Value) -> None:
        """Keep ``value`` (its first element, for a tuple) as the last value written."""
        self.last = float(value[0]) if isinstance(value, tuple) else float(value)
