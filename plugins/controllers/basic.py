"""Two elementary control laws: ``controller.constant`` and ``controller.relay``.

- constant: outputs its ``value`` Param whatever its inputs — a blind fallback (creep forward,
  hold a brake) that a switching criterion can bring in when the sensors fail.
- relay: republishes its single input on its output, optionally scaled (``gain``, ``offset``);
  the cheapest way to bridge a topic into another partition or onto an external topic.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ckmconf.model.kernel import Controller as ControllerRecord
from runtime.kernel.interfaces import Controller, ParamError, read_params
from runtime.verification.manifest import P, Params


class Constant(Controller):
    """Outputs a fixed value."""

    PARAMS = Params(P("value", 0.0, "The output, whatever the inputs."))

    def __init__(self, record: ControllerRecord) -> None:
        super().__init__(record)
        self.value = float(
            read_params(record.params, self.PARAMS, owner=f"controller {record.name!r} (constant)")["value"]
        )

    def step(self, inputs: Mapping[str, float], dt: float) -> float:
        """The ``value`` Param, whatever the inputs."""
        return self.value

    def future(self) -> list[float]:
        """``horizon`` copies of the value."""
        return [self.value] * self.record.horizon


class Relay(Controller):
    """Passes its one input through, as ``gain · input + offset``."""

    PARAMS = Params(P("gain", 1.0, "Factor applied to the input."), P("offset", 0.0, "Added after the gain."))

    def __init__(self, record: ControllerRecord) -> None:
        super().__init__(record)
        owner = f"controller {record.name!r} (relay)"
        values = read_params(record.params, self.PARAMS, owner=owner)
        if len(record.inputs) != 1:
            raise ParamError(f"{owner} relays exactly one input, not {len(record.inputs)}")
        self.gain, self.offset = float(values["gain"]), float(values["offset"])
        self.last = 0.0

    def step(self, inputs: Mapping[str, float], dt: float) -> float:
        """``gain · input + offset`` of the one input."""
        self.last = self.gain * next(iter(inputs.values())) + self.offset
        return self.last

    def future(self) -> list[float]:
        """``horizon`` copies of the last output."""
        return [self.last] * self.record.horizon

    def state(self) -> dict[str, Any]:
        """The last output (code delegation, §3.1.2.6)."""
        return {"last": self.last}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from the last output of ``state()``."""
        self.last = float(state.get("last", 0.0))
