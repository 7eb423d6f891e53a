"""``hardware.loopback``: channels served by a simulated linear plant instead of hardware.

Channels naming the same plant (Param ``plant``; default: the channel's own name) share it: an
output channel (``direction="out"``) drives the plant input u, an input channel reads the plant
output y (``size`` 1). The plant Params may sit on any of its channels (two channels giving one
Param two values is a ParamError): ``order`` 0/1/2 with ``gain``, ``timeConstant``,
``naturalFrequency`` and ``damping`` as in :mod:`plugins.lti` (``order`` defaults to what the other
Params imply, 0 — y = gain·u, a plain loopback — when there are none), ``noise`` (standard
deviation added to each read, from a generator seeded by ``seed``) and ``delay`` (dead time of the
input, seconds). Reading an output channel gives the plant's last input.

Time. On every read and write the plant is integrated exactly (piece-wise constant input) from
the previous access to its scope's clock time, under a lock, so any number of threads may use it.

Isolation. Plants live in a module-level table keyed by (scope, plant name), the scope chosen as
:mod:`plugins.hardware.simulation` says (explicit, ``with plant_scope()``, else per configuration
file and node). The key holds the scope object itself, not its ``id``, so it cannot be reused by a
later scope; plants are weakly held, so a plant goes away with its last backend. A plant lives in
one process: channels in different partitions (processes) cannot share one.
"""

from __future__ import annotations

import random
import threading
import weakref
from collections import deque
from collections.abc import Mapping
from typing import Any

from ckmconf.model import HWChannel, params_dict
from plugins.lti import MODEL_SPEC, PlantModel, Vector, model_from_params
from runtime.kernel.interfaces import Backend, ParamError, Value, read_params
from runtime.verification.manifest import NUMBER, P, Params, Ports

from .simulation import Clock, ManualClock, PlantScope, SimulationHook, plant_scope, scope_for

__all__ = [
    "LoopbackBackend",
    "LoopbackPlant",
    "ManualClock",
    "PlantScope",
    "SimulationHook",
    "find_plant",
    "plant_scope",
    "scope_for",
]

_SPEC = (
    Params(
        P("plant", "", "Name of the simulated plant the channel belongs to (default: the channel's name)."),
        P("order", 0, "Order of the plant (default: what the other Params imply).", choices=(0, 1, 2)),
    )
    | MODEL_SPEC
    | Params(
        P("noise", 0.0, "Standard deviation of the noise added to each read.", min=0.0),
        P("seed", 0, "Seed of the noise generator."),
        P("delay", 0.0, "Dead time of the plant input.", unit="s", min=0.0),
    )
)
_plants: weakref.WeakValueDictionary[tuple[PlantScope, str], LoopbackPlant] = weakref.WeakValueDictionary()
_table_lock = threading.Lock()


def find_plant(name: str, scope: PlantScope) -> LoopbackPlant | None:
    """The plant ``name`` of ``scope`` while a backend holds it (for tests and operator consoles)."""
    with _table_lock:
        return _plants.get((scope, name))


def _implied_order(given: Mapping[str, Any]) -> int:
    if "order" in given:
        return int(given["order"])
    if "naturalFrequency" in given or "damping" in given:
        return 2
    return 1 if "timeConstant" in given else 0


def _check(given: Mapping[str, Any], owner: str) -> PlantModel:
    """The model the plant Params ``given`` describe, with ``noise``/``delay`` range checks."""
    for name in ("noise", "delay"):
        if given.get(name, 0.0) < 0.0:
            raise ParamError(f"{owner}: parameter {name!r} = {given[name]} must not be negative")
    model_params = {k: v for k, v in given.items() if k in MODEL_SPEC or k == "order"}
    return model_from_params(model_params, owner=owner, orders=(0, 1, 2), default_order=_implied_order(given))


class LoopbackPlant(SimulationHook):
    """One simulated plant shared by the loopback channels that name it."""

    def __init__(self, name: str, clock: Clock) -> None:
        super().__init__(clock)
        self.name = name
        self.params: dict[str, Any] = {}
        self._givers: dict[str, str] = {}  # parameter → the channel that gave it
        self.model = PlantModel(order=0)
        self._x: Vector = ()
        self._u = 0.0  # last commanded input
        self._acting = 0.0  # input acting on the plant now (after the dead time)
        self._pending: deque[tuple[float, float]] = deque()  # (time it acts, input)
        self._rng = random.Random(0)

    def attach(self, channel: str, given: Mapping[str, Any]) -> None:
        """Add the plant Params a channel gives; ParamError on a conflict or once running."""
        owner = f"loopback plant {self.name!r}"
        with self.lock:
            for name, value in given.items():
                if name in self.params and self.params[name] != value:
                    raise ParamError(
                        f"{owner}: parameter {name!r} = {value} on channel {channel!r} conflicts with "
                        f"{self.params[name]} on channel {self._givers[name]!r}"
                    )
                if name not in self.params and self.time is not None:
                    raise ParamError(
                        f"{owner}: parameter {name!r} on channel {channel!r} comes after the plant started"
                    )
            merged = {**self.params, **given}
            _check(merged, f"{owner} (Params of its channels together)")
            self.params = merged
            self._givers.update(dict.fromkeys(set(given) - set(self._givers), channel))

    def start(self, now: float) -> None:
        """Build the plant model from its channels' Params and start it at rest, at equilibrium for u = 0."""
        self.model = _check(self.params, f"loopback plant {self.name!r}")
        self._x = self.model.equilibrium(0.0)
        self._rng = random.Random(self.params.get("seed", 0))

    def advance(self, start: float, end: float) -> None:
        """Integrate the plant exactly from ``start`` to ``end``, each delayed input acting from its time."""
        t = start
        while self._pending and self._pending[0][0] <= end:
            at, u = self._pending.popleft()
            if at > t:
                self._x, t = self.model.advance(self._x, self._acting, at - t), at
            self._acting = u
        self._x = self.model.advance(self._x, self._acting, end - t)

    def set_input(self, u: float) -> None:
        """Drive the plant input (after the dead time ``delay``)."""
        with self.lock:
            now = self.sync()
            self._u = u
            delay = self.params.get("delay", 0.0)
            if delay > 0.0:
                self._pending.append((now + delay, u))
            else:
                self._acting = u

    @property
    def input(self) -> float:
        """The last input written."""
        with self.lock:
            return self._u

    def output(self) -> float:
        """The plant output now, with measurement noise when ``noise`` is set."""
        with self.lock:
            self.sync()
            y = self.model.output(self._x, self._acting)
            noise = self.params.get("noise", 0.0)
            return y + self._rng.gauss(0.0, noise) if noise > 0.0 else y


class LoopbackBackend(Backend):
    """A channel served by a simulated linear plant (a :class:`LoopbackPlant`, see the module docstring)."""

    PARAMS = _SPEC
    PORTS = Ports(outputs={"*": NUMBER}, sizes=(1,))

    def __init__(self, channel: HWChannel, *, scope: PlantScope | None = None) -> None:
        super().__init__(channel)
        self.owner = f"loopback channel {channel.name!r}"
        if channel.size != 1:
            raise ParamError(f"{self.owner}: size is {channel.size}, a loopback plant has one output (size 1)")
        values = read_params(channel.params, _SPEC, owner=self.owner)
        given = params_dict(channel.params)
        self.plant_name: str = values["plant"] or channel.name
        self.plant_params = {name: values[name] for name in given if name != "plant"}
        _check(self.plant_params, self.owner)
        self.scope = scope if scope is not None else scope_for(channel)
        self.plant: LoopbackPlant | None = None

    def setup(self) -> None:
        """Join the plant the ``<HWChannel>`` names in its scope (creating it) and give it the channel's Params."""
        key = (self.scope, self.plant_name)
        with _table_lock:
            plant = _plants.get(key)
            if plant is None:
                plant = _plants[key] = LoopbackPlant(self.plant_name, self.scope.clock)
        plant.attach(self.channel.name, self.plant_params)
        self.plant = plant

    def _require(self) -> LoopbackPlant:
        if self.plant is None:
            raise RuntimeError(f"{self.owner} is used before setup() or after stop()")
        return self.plant

    def read(self) -> Value:
        """The plant output y now (an input channel), or the plant's last input u (an output channel)."""
        plant = self._require()
        return plant.input if self.channel.direction == "out" else plant.output()

    def write(self, value: Value) -> None:
        """Drive the plant input u (a ``direction="out"`` channel only; one value)."""
        plant = self._require()
        if self.channel.direction != "out":
            raise RuntimeError(f"{self.owner} is an input channel; drive its plant with find_plant(…).set_input()")
        if isinstance(value, tuple):
            if len(value) != 1:
                raise ValueError(f"{self.owner} takes one value, got {len(value)}")
            value = value[0]
        plant.set_input(float(value))

    def stop(self) -> None:
        """Let go of the plant (it goes away with the last channel holding it)."""
        self.plant = None
