"""The world a run's sim channels describe (issue J point 5, decision D101): what the world server
(and its render worker's mirror) build, read from the channels before anything starts."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from ckmconf import ConfigError, load
from ckmconf.model import HWChannel, Node
from runtime.kernel.interfaces import ParamError

from .devices import SimWorld


@dataclass
class WorldPlan:
    """What the server builds, read from the run's sim channels in document order (D101): the first
    channel naming ``world`` (else the first sim channel) decides the world file, seed and textures;
    each robot is loaded, in the order first named, at the ``pose`` (and ``model``) of the first of
    its channels giving one."""

    world: str
    seed: int
    textures: str
    bodies: dict[str, tuple[str, str]] = field(default_factory=dict)  # name → (model, pose)
    cameras: set[str] = field(default_factory=set)  # the bodies carrying an rgb or depth sensor

    @classmethod
    def of(cls, nodes: list[Node]) -> WorldPlan | None:
        """The plan of ``nodes``' sim channels (None without any); ConfigError located at a channel
        whose Params are wrong or that names another world than the one already chosen."""
        from plugins.hardware.sim import SimBackend  # the backend reads the Params (one code path)

        backends: list[tuple[HWChannel, SimBackend]] = []
        for channel in (ch for node in nodes for ch in node.channels if ch.backend == "sim"):
            try:
                backends.append((channel, SimBackend(channel)))
            except ParamError as exc:
                raise ConfigError.of(channel, str(exc)) from None
        if not backends:
            return None
        named = [(ch, b) for ch, b in backends if b.values["world"]]
        first_channel, first = named[0] if named else backends[0]
        for channel, backend in named[1:]:
            if backend.world_file != first.world_file:
                raise ConfigError.of(
                    channel,
                    f"sim channel {channel.name!r}: Param 'world' names {backend.world_file}, "
                    f"but channel {first_channel.name!r} already chose {first.world_file}: "
                    "a run has one simulated world",
                )
        plan = cls(first.world_file, int(first.values["seed"]), first._path(first.values["textures"]))
        for _, backend in backends:
            spec = backend.spec().values
            model, pose = plan.bodies.get(spec["body"], ("", ""))
            plan.bodies[spec["body"]] = (model or spec["model"], pose or spec["pose"])
            if backend.values["sensor"] in ("rgb", "depth"):  # one render gives a body's colour and depth
                plan.cameras.add(spec["body"])
        return plan

    def build(self) -> SimWorld:
        """The world, on real time, with every robot of the plan loaded."""
        environment = load(self.world).environment if self.world else None
        sim = SimWorld(time.monotonic, environment, self.seed, self.textures, self.world)
        for name, (model, pose) in self.bodies.items():
            sim.robot(name, model, pose)
        return sim
