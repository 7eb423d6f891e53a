"""Base classes plugins implement: hardware backends, adaptation functions, controllers.

Each is built from its configuration record with no I/O in ``__init__``; hardware opens in
``setup()`` and closes in ``stop()``. Values are floats (or tuples of floats for channels whose
``size`` is more than one). Each class declares its Params and ports once, at the class
(``PARAMS``, ``PORTS``: see :mod:`runtime.verification.manifest`); ``read_params`` converts the
``<Param>`` elements against that declaration, and ``verify`` checks configurations against it.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy.typing as npt

from ckmconf.model import HWChannel
from ckmconf.model.kernel import Controller as ControllerRecord

from ..verification.manifest import NUMBER, NUMBERS, ParamError, Params, Ports, read_params

Value = float | tuple[float, ...] | npt.NDArray[Any]
"""A raw read: one number, a tuple of numbers, or a flat numpy array (a camera frame or a scan read
whole: a 921,600-element tuple cost 45 ms to make and 20 ms to turn back into an array, D243)."""


class Backend(abc.ABC):
    """The hardware behind one HWChannel (loopback plant, pybullet joint or camera, a real bus…)."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params()
    PORTS: ClassVar[Ports] = Ports(outputs={"*": NUMBERS})

    def __init__(self, channel: HWChannel) -> None:
        self.channel = channel

    def setup(self) -> None:
        """Open the device (no I/O before this)."""
        return None  # optional hook

    latency: float = 0.0
    """Seconds from a read's request to its value (a simulated camera's transfer, D246). With a
    latency the sensor reads in two phases: :meth:`request` at its instant, :meth:`collect` that
    much later, the value stamped at the request; the world runs on meanwhile."""

    @abc.abstractmethod
    def read(self) -> Value:
        """The current raw value of an input channel."""

    def request(self) -> Any:
        """Start a read now (a backend with a ``latency``); what :meth:`collect` takes. By default the value."""
        return self.read()

    def collect(self, token: Any) -> Value:
        """The value of the read :meth:`request` started (waiting for it if need be)."""
        value: Value = token
        return value

    @abc.abstractmethod
    def write(self, value: Value) -> None:
        """Drive an output channel to a raw value (already within the channel's range)."""

    def stop(self) -> None:
        """Close the device; output channels have already been driven to their safe value."""
        return None  # optional hook


class AdaptationFunction(abc.ABC):
    """One step of an adaptation chain: raw → engineering units (sensors) or back (actuators)."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params()

    @abc.abstractmethod
    def __call__(self, value: float, now: float) -> float:
        """Transform one value; ``now`` (seconds, monotonic) lets filters account for time."""

    def reset(self) -> None:
        """Forget any history (filters)."""
        return None  # optional hook

    def inverse(self) -> AdaptationFunction:
        """The step that undoes this one, for actuators; a filter or limit acts as itself."""
        return self


class Controller(abc.ABC):
    """A control law (§3.1.2.2). ``step`` gives the action; ``future`` the stored next actions."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params()
    PORTS: ClassVar[Ports] = Ports(inputs={"*": NUMBER}, outputs={"*": NUMBER})

    def __init__(self, record: ControllerRecord) -> None:
        self.record = record

    @abc.abstractmethod
    def step(self, inputs: Mapping[str, float], dt: float) -> float:
        """The action for this period from inputs by role (measure, setpoint, …)."""

    def future(self) -> list[float]:
        """Actions for the next ``horizon`` periods, as predicted now (played if inputs are lost)."""
        return []

    def bumpless(self, output: float) -> None:
        """Take over from another controller whose last output was ``output``."""
        return None  # optional hook

    def state(self) -> dict[str, Any]:
        """The controller's internal state, msgpack-able (for delegation to another node)."""
        return {}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a state produced by ``state()`` on another node."""
        return None  # optional hook


__all__ = [
    "AdaptationFunction",
    "Backend",
    "Controller",
    "ParamError",
    "Value",
    "read_params",
]
