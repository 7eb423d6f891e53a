"""The record checks (``problems``, D268, D307) of navigate-to, fly-to and dock-robot: one goal source,
an input that is one of the behavior's, a dock the docking service it uses knows. Each is run on the
records of two systems: the depot relay (configs/relay: the scout, the rover and the quad) and the
configurations of the examples (the bring-your-own-robot scout, the aerial example's UAVs)."""

from __future__ import annotations

from dataclasses import replace

import pytest

import ckmconf
from ckmconf.model import System
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.params import Param
from plugins.behaviors.docking import DockRobot, UndockRobot
from plugins.behaviors.flight import FlyTo
from plugins.behaviors.navigate import NavigateTo
from tests.conftest import REPO

RELAY = REPO / "configs" / "relay" / "relay.xml"
SCOUT = REPO / "configs" / "examples" / "byor" / "scout.xml"
UAVS = REPO / "configs" / "examples" / "aerial" / "uavs.xml"


@pytest.fixture(scope="module")
def relay() -> System:
    return ckmconf.load(RELAY)


def behavior(system: System, name: str) -> BehaviorRecord:
    found = system.behavior(name)
    assert found is not None, name
    return found


def with_params(record: BehaviorRecord, **values: str | None) -> BehaviorRecord:
    """``record`` with each Param of ``values`` set (None: removed)."""
    kept = [p for p in record.params if p.name not in values]
    added = [Param(name=k, value=v) for k, v in values.items() if v is not None]
    return replace(record, params=(*kept, *added))


def messages(found: list[tuple[object, str]]) -> list[str]:
    return [message for _, message in found]


def test_the_reference_systems_behaviors_have_no_problem(relay: System) -> None:
    for name, kind in (("ROVER_TO_SCOUT", NavigateTo), ("SCOUT_TO_PICKUP", NavigateTo), ("QUAD_OVER_SCOUT", FlyTo),
                       ("QUAD_TO_PAD", FlyTo), ("ROVER_DOCK", DockRobot), ("ROVER_UNDOCK", UndockRobot)):
        assert kind.problems(behavior(relay, name), relay) == [], name
    scout, uavs = ckmconf.load(SCOUT), ckmconf.load(UAVS)
    assert NavigateTo.problems(behavior(scout, "TO_PALLET"), scout) == []
    assert FlyTo.problems(behavior(uavs, "HEXA_CROSS"), uavs) == []


@pytest.mark.parametrize(("name", "params", "message"), [
    ("ROVER_TO_SCOUT", {"input": "scout_pose"},
     "parameter 'input' = 'scout_pose' is not one of its inputs (['scout'])"),
    ("ROVER_TO_SCOUT", {"goal": "Pickup"}, "give the goal either as parameter 'goal' or through parameter 'input'"),
    ("SCOUT_TO_PICKUP", {"goal": None}, "give the goal either as parameter 'goal' or through parameter 'input'"),
])
def test_navigate_to_takes_one_goal_source_and_its_own_input(relay: System, name: str,
                                                              params: dict[str, str | None], message: str) -> None:
    found = NavigateTo.problems(with_params(behavior(relay, name), **params), relay)
    assert len(found) == 1 and found[0][1].startswith(message), found


def test_navigate_to_on_the_byor_scout_refuses_a_goal_and_an_input_together() -> None:
    scout = ckmconf.load(SCOUT)
    record = with_params(behavior(scout, "TO_PALLET"), input="pallet")
    assert messages(NavigateTo.problems(record, scout)) == [
        "give the goal either as parameter 'goal' or through parameter 'input', one of the two"]


def test_fly_to_takes_a_goal_or_an_input_with_an_altitude(relay: System) -> None:
    over = behavior(relay, "QUAD_OVER_SCOUT")  # an input: the scout's signal
    assert messages(FlyTo.problems(with_params(over, goal="9 6 2.8"), relay)) == [
        "give parameter 'goal' or an input to fly over, not both"]
    assert messages(FlyTo.problems(with_params(over, altitude=None), relay)) == [
        "flying over a received position needs parameter 'altitude'"]
    uavs = ckmconf.load(UAVS)  # the hexarotor's cross: no input
    assert messages(FlyTo.problems(with_params(behavior(uavs, "HEXA_CROSS"), goal=None), uavs)) == [
        "parameter 'goal' is required (or an input to fly over)"]


def test_dock_robot_names_a_dock_its_docking_service_knows(relay: System) -> None:
    dock = behavior(relay, "ROVER_DOCK")
    found = DockRobot.problems(with_params(dock, dock="chargr"), relay)
    assert messages(found) == ["parameter 'dock' = 'chargr' is no dock of the docking service RoverDock.Dock "
                               "(its docks: charger); did you mean 'charger'?"]
    assert found[0][0].name == "dock"  # located at the Param
    assert messages(DockRobot.problems(with_params(dock, pose="11.1 2.0 0"), relay)) == [
        "give the dock's name ('dock') or its docked pose ('pose'), one of them"]
    assert DockRobot.problems(with_params(dock, dock=None, pose="11.1 2.0 0"), relay) == []  # a dock by its pose
    # Without the system (as a behavior is built) only the Params themselves are checked.
    assert DockRobot.problems(with_params(dock, dock="chargr"), None) == []
