"""``controller.hysteresis``: an on/off controller with a dead band (the controller example).

Inputs by role: ``measure`` (required) and ``setpoint`` (0 when absent). The output switches to
``high`` when the measure falls below ``setpoint − band/2`` and to ``low`` when it rises above
``setpoint + band/2``; in between it keeps its last value, so it does not chatter.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model.kernel import Controller as ControllerRecord
from runtime.kernel.interfaces import Controller, ParamError, read_params
from runtime.verification.manifest import NUMBER, P, Params, Ports


class Hysteresis(Controller):
    """An on/off (bang-bang) control law with a dead band around the set point."""

    PARAMS: ClassVar[Params] = Params(
        P("band", 0.1, "Width of the dead band around the set point.", min=0.0),
        P("high", 1.0, "Output while the measure is too low."),
        P("low", 0.0, "Output while the measure is too high."),
    )
    PORTS: ClassVar[Ports] = Ports(inputs={"measure": NUMBER, "setpoint": NUMBER}, outputs={"*": NUMBER})

    def __init__(self, record: ControllerRecord) -> None:
        super().__init__(record)
        self.owner = f"controller {record.name!r} (hysteresis)"
        values = read_params(record.params, self.PARAMS, owner=self.owner)
        if not values["low"] < values["high"]:  # a check across Params: the kind's own, at build time
            raise ParamError(f"{self.owner}: 'low' = {values['low']} must be below 'high' = {values['high']}")
        self.band: float = values["band"]
        self.high: float = values["high"]
        self.low: float = values["low"]
        self.output: float = self.low

    def step(self, inputs: Mapping[str, float], dt: float) -> float:
        """The action for this period (kernel.xsd ``Controller``, §3.1.2.2): ``high``, ``low`` or the last output.

        Raises:
            KeyError: there is no ``measure`` input.
        """
        if "measure" not in inputs:
            raise KeyError(f"{self.owner}: no input with role 'measure'")
        error = float(inputs.get("setpoint", 0.0)) - float(inputs["measure"])
        if error > self.band / 2.0:
            self.output = self.high
        elif error < -self.band / 2.0:
            self.output = self.low
        return self.output

    def future(self) -> list[float]:
        """``horizon`` copies of the current output, played if the inputs are lost."""
        return [self.output] * self.record.horizon

    def state(self) -> dict[str, Any]:
        """The current output: all the state code delegation (§3.1.2.6) must carry."""
        return {"output": self.output}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()`` taken on another node."""
        self.output = float(state["output"])
