"""``behavior.survey-area`` (issue N point 3a; D302): an Area's lawnmower waypoints as flight goals, each
followed by its own id only; a candidate of the wanted label held and confirmed over further frames
before it is taken, distractors of other labels and a lone noisy frame never ending the survey; the
confirmed map position written on every report output. In flight on both UAV models:
tests/plugins/flight/test_survey_example.py."""

from __future__ import annotations

import math
from typing import Any

import pytest

from ckmconf.model import Param
from ckmconf.model.environment import Area, Environment, MapBounds, Vertex
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.missions import BehaviorOutput, Uses
from plugins.behaviors.survey_area import SurveyArea
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext
from tests.memory_service import MemoryService

YARD = Area(name="Yard", vertices=tuple(Vertex(x=x, y=y) for x, y in ((0, 0), (6, 0), (6, 4), (0, 4))))
ENVIRONMENT = Environment(name="yard", map=MapBounds(xmin=0, ymin=0, xmax=6, ymax=4), areas=(YARD,))


def record(outputs: tuple[str, ...] = ("flight_goal", "parcel"), **params: str) -> BehaviorRecord:
    values = {"area": "Yard", "altitude": "3", "spacing": "2", "label": "red", "confirmFrames": "2",
              "confirmTime": "4", **params}
    return BehaviorRecord(name="SURVEY", kind="survey-area", timeout=600.0,
                          params=tuple(Param(name=k, value=v) for k, v in values.items()),
                          uses=(Uses(service="Uav.Flight", as_="flight"), Uses(service="Uav.Ground", as_="detection")),
                          outputs=tuple(BehaviorOutput(name=n, topic=f"/{n}") for n in outputs))


class Bench:
    """The behavior on an in-memory flight service and detector; what it writes, per output."""

    def __init__(self, **params: str) -> None:
        self.flight, self.eyes, self.clock = MemoryService("Uav.Flight"), MemoryService("Uav.Ground"), [0.0]
        self.flight.outputs["pose"] = {"stamp": 0.0, "frame": "map", "pose": {"x": 1, "y": 1, "z": 3, "yaw": 0.0}}
        self.written: dict[str, list[Any]] = {"flight_goal": [], "parcel": []}
        context = BehaviorContext(services={"flight": self.flight, "detection": self.eyes}, inputs={},
                                  outputs={n: self.written[n].append for n in self.written},
                                  now=lambda: self.clock[0], environment=ENVIRONMENT)
        self.survey = SurveyArea(record(("flight_goal", "parcel"), **params), context)
        self.survey.start()

    def goal(self) -> dict[str, Any]:
        return dict(self.written["flight_goal"][-1])

    def status(self, state: str, goal_id: Any = None, reason: str = "") -> None:
        self.flight.outputs["status"] = {"id": self.goal()["id"] if goal_id is None else goal_id, "state": state,
                                         "reason": reason}

    def see(self, *objects: tuple[str, float, float, float]) -> None:
        """A new detection result (a new object), objects (label, x, y, reliability) on the map."""
        self.eyes.outputs["objects"] = {"objects": [{"name": n, "label": n, "frame": "map", "x": x, "y": y,
                                                     "z": 0.3, "reliability": r} for n, x, y, r in objects]}


def test_each_waypoint_is_a_goto_at_the_altitude_and_only_its_own_status_counts() -> None:
    bench = Bench()
    first = bench.goal()
    assert (first["action"], first["frame"], first["x"], first["y"], first["z"]) == ("goto", "map", 1.0, 1.0, 3.0)
    assert math.isnan(first["yaw"])  # the heading is kept
    assert [(x, y) for x, y, _ in bench.survey.waypoints] == [(1, 1), (3, 1), (5, 1), (5, 3), (3, 3), (1, 3)]
    bench.status("arrived", goal_id=first["id"] - 1)  # an earlier goal's
    assert bench.survey.step().progress == 0.0 and bench.goal() == first
    bench.status("arrived")
    status = bench.survey.step()
    second = bench.goal()
    assert status.progress == pytest.approx(1 / 6) and second["id"] > first["id"] and second["x"] == 3.0


def test_distractors_and_a_lone_noisy_frame_never_end_it_and_the_sweep_flies_on() -> None:
    bench = Bench()
    waypoint = bench.goal()
    bench.see(("green", 2.0, 1.0, 0.95), ("blue", 2.5, 1.2, 0.9), ("red", 2.2, 1.5, 0.3))  # red too unreliable
    assert not bench.survey.step().done and bench.goal() == waypoint  # nothing held
    bench.see(("red", 2.2, 1.5, 0.9))  # one frame
    assert not bench.survey.step().done and bench.goal()["action"] == "hold"
    bench.see(("red", 3.5, 1.5, 0.9))  # 1.3 m from the candidate: no confirmation
    bench.see(("green", 2.2, 1.5, 0.9))
    assert not bench.survey.step().done
    bench.clock[0] = 4.5  # confirmTime over: the candidate is dropped, the waypoint flown again
    status = bench.survey.step()
    again = bench.goal()
    assert not status.done and again["action"] == "goto" and (again["x"], again["y"]) == (1.0, 1.0)
    assert again["id"] > waypoint["id"] and not bench.written["parcel"]
    assert {"message": "candidate not confirmed", "label": "red", "confirmations": 0} in bench.survey.context.events


def test_a_confirmed_object_is_reported_at_the_mean_of_its_sightings_while_hovering() -> None:
    bench = Bench()
    for k, (x, y) in enumerate([(4.0, 3.0), (4.1, 3.1), (3.9, 3.05)]):
        bench.see(("blue", 1.0, 1.0, 0.99), ("red", x, y, 0.8 + 0.05 * k))
        status = bench.survey.step()
        if k == 0:
            held = bench.goal()
        assert status.done == (k == 2)
    assert held["action"] == "hold" and bench.goal() == held  # still hovering where it stopped
    (found,) = bench.written["parcel"]
    assert (found["label"], found["frame"]) == ("red", "map")
    assert (found["x"], found["y"], found["z"]) == pytest.approx((4.0, 3.05, 0.3))
    assert found["reliability"] == pytest.approx(0.85)
    assert status.detail == "red at (4.00, 3.05)" and bench.survey.step().done
    assert found["observer"] == []  # a map position from the detector: placed already
    bench.survey.stop()
    assert bench.goal() == held  # nothing more sent


def test_results_from_before_the_state_never_count() -> None:
    bench = Bench()
    bench.see(("red", 4.0, 3.0, 0.9))
    bench.survey.start()  # the same result, left from before
    bench.survey.step()
    assert bench.goal()["action"] == "goto"


def test_a_failed_waypoint_is_skipped_with_its_reason_and_the_covered_area_fails() -> None:
    bench = Bench()
    for k in range(6):
        if k == 3:
            bench.status("failed", reason="the flight's leg 1 meets 'mast'")
        else:
            bench.status("arrived")
        status = bench.survey.step()
    assert status.failed and status.progress == 1.0 and not bench.written["parcel"]
    assert "covered (6 waypoints, 1 skipped) without finding red; skipped 5.00 3.00: the flight failed: the " \
           "flight's leg 1 meets 'mast'" in status.detail


def test_leaving_mid_sweep_holds_and_a_robot_frame_sighting_is_placed_with_the_flight_pose() -> None:
    bench = Bench(sensorPose="0.1 0 0")
    bench.flight.outputs["pose"] = {"pose": {"x": 2.0, "y": 2.0, "z": 3.0, "yaw": math.pi / 2}}
    bench.eyes.outputs["objects"] = {"objects": [{"name": "red", "x": 1.0, "y": 0.0, "reliability": 0.9}]}
    bench.survey.step()
    assert bench.survey.candidates[0][:2] == pytest.approx((2.0, 3.1))  # 1.1 m ahead, facing +y
    bench.clock[0] = 10.0
    bench.survey.step()  # not confirmed: back to the sweep
    bench.survey.stop()
    assert bench.goal()["action"] == "hold"


@pytest.mark.parametrize(("outputs", "params", "message"), [
    (("parcel",), {}, 'it flies through its <Output name="flight_goal">'),
    (("flight_goal",), {}, "give an <Output> (a topic or a plan signal) for the object's map position"),
])
def test_a_survey_without_its_goal_or_report_output_is_refused(outputs: tuple[str, ...], params: dict[str, str],
                                                               message: str) -> None:
    assert message in SurveyArea.problems(record(outputs, **params), None)[0][1]
    context = BehaviorContext(services={}, inputs={}, outputs={}, now=lambda: 0.0, environment=ENVIRONMENT)
    with pytest.raises(ParamError, match="survey-area"):
        SurveyArea(record(outputs), context)
