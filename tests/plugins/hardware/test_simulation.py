"""Simulated time and isolation: the default scope per node, and the lazily advanced world."""

from __future__ import annotations

import dataclasses

from ckmconf.errors import Loc
from plugins.hardware.loopback import LoopbackBackend
from plugins.hardware.simulation import ManualClock, SimulationHook
from tests.plugins.hardware.test_loopback import channel


def test_without_a_scope_channels_of_one_node_share_a_plant() -> None:
    def at(node: str, name: str) -> Loc:
        return Loc("plant.xml", 1, 1, f"/System/Node[@name='{node}']/HWChannel[@name='{name}']")

    out = LoopbackBackend(dataclasses.replace(channel("u", "out", plant="p"), loc=at("a", "u")))
    same_node = LoopbackBackend(dataclasses.replace(channel("y", plant="p"), loc=at("a", "y")))
    other_node = LoopbackBackend(dataclasses.replace(channel("y", plant="p"), loc=at("b", "y")))
    assert out.scope is same_node.scope is not other_node.scope


class CountingWorld(SimulationHook):
    """What a physics backend does: step a fixed-step engine as far as the clock went."""

    STEP = 0.25

    def __init__(self, clock: ManualClock) -> None:
        super().__init__(clock)
        self.steps = 0
        self.intervals: list[tuple[float, float]] = []

    def advance(self, start: float, end: float) -> None:
        self.intervals.append((start, end))
        self.steps = int((end - self.intervals[0][0]) / self.STEP)


def test_simulation_hook_advances_lazily_and_never_backwards() -> None:
    clock = ManualClock(10.0)
    world = CountingWorld(clock)
    with world.lock:
        assert world.sync() == 10.0
        clock.advance(0.6)
        world.sync()
        world.sync()  # no time passed: no advance
        clock.now = 9.0  # a clock going back does not move the world back
        assert world.sync() == 10.6
    assert world.intervals == [(10.0, 10.6)]
    assert world.steps == 2
