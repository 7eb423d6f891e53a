"""Controllers with several outputs and message-valued inputs (§3.1.2.2): the vector protocol.

A ``<Controller>`` with several ``<Output>`` elements gives one value per output, in document
order. Such controllers derive from :class:`MultiOutputController` and implement
``step_outputs`` (one value per output) and ``future_outputs`` (``horizon`` rows of them); the
control service must publish value *i* on output *i* and store column *i* as that output's future
actions. ``step`` is kept for single-output controllers only: writing one value onto every output
would drive a differential base's two wheels alike, so for several outputs it refuses (D91).

Inputs are keyed by role. A role given to several ``<Input>`` elements (the two wheel speeds of
the use case, both ``role="measure"``) is keyed ``role[0]``, ``role[1]``, … in document order
(:func:`role_values` reads either form). Inputs may be messages (mappings of their fields) as
well as numbers.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Mapping, Sequence
from typing import Any

from ckmconf.model.kernel import Controller as ControllerRecord
from runtime.kernel.interfaces import Controller, ParamError

Row = tuple[Any, ...]


def role_values(inputs: Mapping[str, Any], role: str) -> list[Any]:
    """The values of the inputs with ``role``, in document order (``role`` or ``role[0]``, ``role[1]``…)."""
    if role in inputs:
        return [inputs[role]]
    values: list[Any] = []
    while f"{role}[{len(values)}]" in inputs:
        values.append(inputs[f"{role}[{len(values)}]"])
    return values


def input_roles(record: ControllerRecord) -> list[str]:
    """The role of each ``<Input>`` (its topic when it has none), in document order."""
    return [port.role or port.topic for port in record.inputs]


def numbers(text: str, *, name: str, owner: str, count: int | None = None) -> list[float]:
    """A whitespace-separated list of numbers from a string Param (one number may stand for all ``count``)."""
    try:
        values = [float(item) for item in text.split()]
    except ValueError:
        raise ParamError(f"{owner}: parameter {name!r} = {text!r} is not a list of numbers") from None
    if count is not None and len(values) == 1 and count > 1:
        values = values * count
    if count is not None and len(values) != count:
        raise ParamError(f"{owner}: parameter {name!r} has {len(values)} values, one per joint ({count}) is needed")
    return values


def field(value: Any, name: str, *, owner: str, what: str) -> float:
    """A numeric field of a message (a mapping), with a clear error when it is not there."""
    if not isinstance(value, Mapping) or name not in value:
        raise TypeError(f"{owner}: the {what} must be a message with field {name!r}, got {value!r}")
    number = float(value[name])
    if not math.isfinite(number):
        raise ValueError(f"{owner}: field {name!r} of the {what} is {number}")
    return number


class MultiOutputController(Controller):
    """A control law with one value per ``<Output>`` (see the module docstring)."""

    kind = ""

    def __init__(self, record: ControllerRecord, outputs: int | None = None) -> None:
        super().__init__(record)
        self.owner = f"controller {record.name!r} ({record.kind})"
        if outputs is not None and len(record.outputs) != outputs:
            raise ParamError(f"{self.owner} writes {outputs} outputs, but {len(record.outputs)} <Output> are given")

    @abc.abstractmethod
    def step_outputs(self, inputs: Mapping[str, Any], dt: float) -> Row:
        """One value per output, in document order, for this period."""

    def future_outputs(self) -> list[Row]:
        """Up to ``horizon`` rows of future values (one per output), as predicted now."""
        return []

    def step(self, inputs: Mapping[str, float], dt: float) -> Any:
        """The one output's value (vector protocol, D91).

        Raises:
            TypeError: the controller writes several outputs; its service must call ``step_outputs``.
        """
        values = self.step_outputs(inputs, dt)
        if len(values) != 1:
            raise TypeError(
                f"{self.owner} writes {len(values)} different outputs: its control service must call "
                "step_outputs() and publish one value per output, not one value onto all of them"
            )
        return values[0]

    def future(self) -> list[float]:
        """The first column of ``future_outputs()`` for one output; empty for several."""
        rows = self.future_outputs()
        return [row[0] for row in rows] if rows and len(rows[0]) == 1 else []

    @staticmethod
    def as_row(output: float | Sequence[float] | None, size: int) -> Row | None:
        """A bumpless output as a row of ``size`` values (None when it does not have that shape)."""
        if output is None:
            return None
        if isinstance(output, int | float):
            return (float(output),) * size if size == 1 else None
        row = tuple(float(v) for v in output)
        return row if len(row) == size else None


def measured_size(record: ControllerRecord, owner: str) -> int:
    """How many outputs a controller has that starts from one ``measure`` input per output (or none).

    Raises:
        ParamError: no output, or a number of measures that is neither 0 nor one per output.
    """
    if not record.outputs:
        raise ParamError(f"{owner} needs at least one <Output>")
    size = len(record.outputs)
    measures = sum(1 for port in record.inputs if port.role == "measure")
    if measures not in (0, size):
        raise ParamError(f"{owner}: give one 'measure' input per output ({size}), in the same order, not {measures}")
    return size


def measured_row(inputs: Mapping[str, Any], size: int) -> Row:
    """The ``measure`` inputs as a row of ``size`` outputs (zeros when they are not all there)."""
    measured = [float(v) for v in role_values(inputs, "measure")]
    return tuple(measured) if len(measured) == size else (0.0,) * size
