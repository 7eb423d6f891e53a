"""A signal that carries a goal, in the pybullet closed loop on the Turtlebot and the rover (issue M, point 3).

One agent's ``emit-signal`` sends a payload built from its Params and from an input (the parcel's map
position); the other agent's ``wait-signal`` ignores the stale message left on the topic before its
state began and a payload of another label, takes the parcel's, and hands it to ``navigate-to``, which
drives the robot there through the real navigation service. The states are stepped as the mission
engine steps them (start, step until done, then the next state), at every physics step of the bench.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from plugins.behaviors.navigate import NavigateTo
from plugins.behaviors.signals import EmitSignal, WaitSignal
from runtime.missions.behaviors import Behavior
from tests.plugins.behaviors.closed_loop import BenchNavigation, wired
from tests.plugins.navigation.loop import ROVER_MODEL, TURTLEBOT_MODEL, Bench, RobotModel, room


@pytest.mark.parametrize("model", [TURTLEBOT_MODEL, ROVER_MODEL], ids=lambda m: m.urdf)
def test_a_goal_carried_by_a_signal_is_driven_to_and_a_stale_one_ignored(tmp_path: Path, model: RobotModel) -> None:
    bench = Bench(room(tmp_path), (1.0, 1.8, 0.0), model=model,
                  nav={"particles": 1000, "initialPose": "1 1.8 0", "initialSpread": "0.05 0.03"})
    try:
        stale = {"label": "parcel", "position": {"frame": "map", "x": 1.0, "y": 3.3}}
        bench.publish("/spotted", stale)  # left by an earlier run of the plan
        tell = wired(bench, EmitSignal, "TELL", {}, {"seen": "/seen"}, {"spotted": "/spotted"},
                     fields="label: parcel; agent: air", take="position: seen", fresh="true")
        wait = wired(bench, WaitSignal, "WAIT", {}, {"spotted": "/spotted"}, {"goal": "/goal"},
                     field="label", equals="parcel")
        go = wired(bench, NavigateTo, "GO", {"nav": BenchNavigation(bench)}, {"goal": "/goal"}, {}, input="goal",
                   standoff="0.3")
        ground: list[Behavior] = [wait, go]
        wait.start()
        tell_started = False
        script = {1.0: ("/spotted", {"label": "box", "position": {"frame": "map", "x": 1.0, "y": 0.8}}),
                  1.5: ("/seen", {"frame": "map", "x": 4.0, "y": 1.8})}
        statuses: list[Any] = []

        def ended() -> bool:
            nonlocal tell_started
            for at in [t for t in script if bench.now >= t]:
                bench.publish(*script.pop(at))
            if bench.now >= 0.5 and not tell_started:
                tell.start()
                tell_started = True
            if tell_started:
                tell.step()
            status = ground[0].step()
            statuses.append((ground[0].name, status))
            if status.failed:
                return True
            if status.done:
                ground.pop(0)
                if not ground:
                    return True
                ground[0].start()
            return False

        assert bench.run(ended, 90.0), f"not ended: {statuses[-1]}, at {bench.truth()}"
        assert statuses[-1][0] == "GO" and statuses[-1][1].done, statuses[-1]
        assert isinstance(wait, WaitSignal) and wait.value == {"label": "parcel", "agent": "air",
                                                               "position": {"frame": "map", "x": 4.0, "y": 1.8}}
        waited = [s for name, s in statuses if name == "WAIT"]
        assert waited[-2].detail.endswith("(1 heard, none matching)")  # the box, not the stale parcel
        x, y, _ = bench.truth()
        assert 0.1 < math.dist((x, y), (4.0, 1.8)) < 0.5  # short of it, by the standoff and the tolerance
    finally:
        bench.close()
