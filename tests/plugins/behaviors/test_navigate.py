"""``behavior.navigate-to`` (issue M, point 3): its goal from a Param or an input, only its own goal's
status, a newer goal preempting an older one without a stale status, the reason of a failure, and in
the pybullet closed loop a map Object reached at its standoff through the real Navigation service."""

from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import Any

import pytest
import shapely

from ckmconf.model import Param
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.missions import BehaviorInput, Uses
from plugins.behaviors.navigate import NavigateTo
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext
from tests.memory_service import MemoryService
from tests.plugins.behaviors.closed_loop import BenchNavigation
from tests.plugins.navigation.loop import ROOM, Bench


def record(inputs: tuple[str, ...] = (), **params: str) -> BehaviorRecord:
    return BehaviorRecord(name="GO", kind="navigate-to", timeout=60.0,
                          params=tuple(Param(name=k, value=v) for k, v in params.items()),
                          uses=(Uses(service="Base.Nav", as_="nav"),),
                          inputs=tuple(BehaviorInput(name=n, signal=n) for n in inputs))


def behavior(nav: Any, inputs: dict[str, Any] | None = None, names: tuple[str, ...] = (),
             **params: str) -> NavigateTo:
    values = inputs if inputs is not None else {}
    context = BehaviorContext(services={"nav": nav}, inputs={n: functools.partial(values.get, n) for n in names},
                              outputs={}, now=lambda: 0.0)
    made = NavigateTo(record(names, **params), context)
    made.start()
    return made


def test_a_param_goal_is_sent_at_once_and_only_its_status_counts() -> None:
    nav = MemoryService("Base.Nav")
    nav.outputs["status"] = {"goal": "HomeArea", "state": "failed", "reason": "no path"}  # the goal before
    go = behavior(nav, goal="Dock")
    assert nav.configured[-1] == ({"goal": "Dock"}, ())  # after the Uses' own (empty) Configure
    assert not go.step().failed
    nav.outputs["status"] = {"goal": "Dock", "state": "active", "path_length": 8.0, "remaining": 2.0}
    assert go.step().progress == pytest.approx(0.75)
    nav.outputs["status"] = {"goal": "Dock", "state": "failed", "path_length": 8.0, "remaining": 2.0,
                             "reason": "no localization for 10 s (no scan received)"}
    failed = go.step()
    assert failed.failed and failed.detail == "navigation to Dock failed: no localization for 10 s (no scan received)"


def test_a_newer_goal_preempts_the_older_without_a_stale_status() -> None:
    nav = MemoryService("Base.Nav")
    first = behavior(nav, goal="1 1 0")
    nav.outputs["status"] = {"goal": "1 1 0", "state": "active", "path_length": 3.0, "remaining": 3.0}
    first.step()
    second = behavior(nav, goal="1 1 0")  # the same goal again: a new navigation (the mission's retry)
    assert nav.configured[-1][0] == {"goal": "1 1 0"}
    assert second.step().detail == "waiting for the navigation to take the goal"  # the first one's status
    nav.outputs["status"] = {"goal": "1 1 0", "state": "arrived", "path_length": 3.0, "remaining": 0.0}
    assert second.step().done


def test_a_position_on_the_input_is_reached_short_of_it_facing_it() -> None:
    nav = MemoryService("Base.Nav")
    values: dict[str, Any] = {}
    go = behavior(nav, values, ("spotted",), input="spotted", standoff="0.5")
    assert go.step().detail == "waiting for the goal" and nav.configured == [({}, ())]
    values["spotted"] = {"position": {"frame": "map", "x": 4.0, "y": 5.0, "z": 0.3}}
    assert go.step().detail == "waiting for the goal"  # the robot's pose first
    nav.outputs["pose"] = {"pose": {"x": 1.0, "y": 1.0, "yaw": 0.0}}
    go.step()
    x, y, yaw = map(float, nav.configured[-1][0]["goal"].split())
    assert math.dist((x, y), (4.0, 5.0)) == pytest.approx(0.5, abs=2e-3)
    assert yaw == pytest.approx(math.atan2(4.0, 3.0), abs=1e-3)


def test_a_goal_string_on_the_input_is_sent_as_it_is() -> None:
    nav = MemoryService("Base.Nav")
    go = behavior(nav, {"where": "parcel_7"}, ("where",), input="where")
    go.step()
    assert nav.configured[-1] == ({"goal": "parcel_7"}, ())


@pytest.mark.parametrize(
    ("params", "names", "message"),
    [
        ({}, (), "give the goal either as parameter 'goal' or through parameter 'input'"),
        ({"goal": "Dock", "input": "where"}, ("where",), "one of the two"),
        ({"input": "wher"}, ("where",), "parameter 'input' = 'wher' is not one of its inputs (['where'])"),
        ({"goal": "Dock", "standoff": "-1"}, (), "must not be negative"),
    ],
)
def test_a_goal_given_twice_nowhere_or_from_no_input_is_refused(params: dict[str, str], names: tuple[str, ...],
                                                                 message: str) -> None:
    context = BehaviorContext(services={"nav": MemoryService("Base.Nav")}, inputs={}, outputs={}, now=lambda: 0.0)
    with pytest.raises(ParamError, match="behavior 'GO' \\(navigate-to\\)") as caught:
        NavigateTo(record(names, **params), context)
    assert message in str(caught.value)


def test_in_the_closed_loop_navigate_to_an_object_ends_at_its_standoff(tmp_path: Path) -> None:
    parcel = ('    <Semantic tag="parcel" landmark="free" dynamic="static"/>\n'
              '    <Object name="parcel" tag="parcel"><Pose x="3.9" y="0.9" z="0" yaw="0"/><Geometry3D>'
              '<Prism zmin="0" zmax="0.3"><Rectangle width="0.3" depth="0.3"/></Prism></Geometry3D></Object>\n')
    room = tmp_path / "room.xml"
    room.write_text(ROOM.replace("  </Environment>", parcel + "  </Environment>"))
    bench = Bench(room, (1.0, 1.8, 0.0), nav={"particles": 1000, "initialPose": "1 1.8 0",
                                             "initialSpread": "0.05 0.03"})
    try:
        go = behavior(BenchNavigation(bench), goal="parcel")
        statuses: list[Any] = []

        def ended() -> bool:
            statuses.append(go.step())
            return bool(statuses[-1].done or statuses[-1].failed)

        assert bench.run(ended, 60.0), f"not ended: {statuses[-1]}, at {bench.truth()}"
        assert statuses[-1].done, statuses[-1]
        assert max(s.progress for s in statuses[:-1]) > 0.5  # the path's share covered, as it drove
        x, y, _ = bench.truth()
        gap = shapely.box(3.75, 0.75, 4.05, 1.05).distance(shapely.Point(x, y)) - 0.18
        assert 0.0 < gap < 0.28
    finally:
        bench.close()
