"""Service states and the Services Performance Composition of eq. 5.1 on Table 7.6 (D13)."""

from __future__ import annotations

from pathlib import Path

import pytest

import ckmconf
from ckmconf.model.missions import CompositionMatrix, MatrixService, Require, Row, Uses
from runtime.missions.composition import composed_performance, service_performance

REPO = Path(__file__).resolve().parents[3]


def test_service_state_is_zero_when_not_running_and_one_when_every_requirement_holds() -> None:
    requirement = Require(measure="reliability", lower=0.5, probability=0.8)
    assert service_performance(False, [requirement], {"reliability": [0.9] * 10}) == 0.0
    assert service_performance(True, [requirement], {"reliability": [0.9] * 10}) == 1.0
    # 6 of 10 samples within bounds: P = 0.6, required 0.8 → 0.75.
    assert service_performance(True, [requirement], {"reliability": [0.9] * 6 + [0.1] * 4}) == pytest.approx(0.75)
    assert service_performance(True, [requirement], {}) == 0.0  # running but silent on what it was asked
    assert service_performance(True, [], {}) == 1.0


def test_table_7_6_rows_are_normalised_weighted_means() -> None:
    lab = ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")
    matrix = lab.matrix("turtlebot")
    assert matrix is not None
    sp = {"LaserSensor.Scan": 1.0, "MobileBase.Displacement": 0.5, "Navigation.AMCL": 0.2,
          "RGBDCamera.RGBRecog": 0.8, "RGBDCamera.DepthRecog": 0.4, "GlobalRecog.Fusion": 0.9}  # fmt: skip
    # WAIT uses AMCL, Scan, Displacement (Table 7.5):
    #   P_AMCL = (Scan + Displ + AMCL) / 3 = 0.5667; P_Scan = 1; P_Displ = (Scan + Displ) / 2 = 0.75.
    wait = composed_performance(matrix, ["Navigation.AMCL", "LaserSensor.Scan", "MobileBase.Displacement"], sp)
    assert wait == pytest.approx((1.7 / 3 + 1.0 + 0.75) / 3)
    # SPOT uses RGB, Depth, Fusion: P_Fusion = (0.5·RGB + 0.5·Depth + Fusion) / 2 = 0.75.
    spot = composed_performance(matrix, ["RGBDCamera.RGBRecog", "RGBDCamera.DepthRecog", "GlobalRecog.Fusion"], sp)
    assert spot == pytest.approx((0.8 + 0.4 + 0.75) / 3)


def test_without_a_matrix_or_a_row_a_service_counts_alone() -> None:
    assert composed_performance(None, ["a.b", "c.d"], {"a.b": 1.0, "c.d": 0.5}) == 0.75
    assert composed_performance(None, [], {}) is None
    strict = CompositionMatrix(
        name="m", rule="strict", services=(MatrixService(ref="a.b"),), rows=(Row(values=(1.0,)),)
    )
    assert composed_performance(strict, ["a.b", "x.y"], {"a.b": 0.4}) == pytest.approx(0.2)  # x.y not running


class KnownService:
    """A service handle with a known state: running, and ``value`` for every measure it is asked for."""

    def __init__(
        self, ref: str, value: float, running: bool = True, per_measure: dict[str, float] | None = None
    ) -> None:
        self.ref, self.value, self._running, self.per_measure = ref, value, running, per_measure or {}

    def configure(self, parameters: object, requirements: object) -> None:
        return None

    def output(self, name: str) -> None:
        return None

    def measures(self) -> dict[str, float]:
        return {}

    def samples(self, measure: str) -> list[float]:
        return [self.per_measure.get(measure, self.value)] * 10

    def running(self) -> bool:
        return self._running


def compliant(uses: Uses) -> KnownService:
    """A running service whose samples sit inside every bound the behavior requires of it."""
    inside = {r.measure: r.lower if r.lower is not None else (r.upper or 0.0) / 2 for r in uses.requires}
    return KnownService(uses.service, 1.0, per_measure=inside)


# Table 7.6, rows (normalised, D13) over MoveIt Scan RGB Depth Displ AMCL Fusion.
TABLE_7_6 = {
    "RoboticArm.MoveIt": {"RoboticArm.MoveIt": 1.0},
    "LaserSensor.Scan": {"LaserSensor.Scan": 1.0},
    "RGBDCamera.RGBRecog": {"RGBDCamera.RGBRecog": 1.0},
    "RGBDCamera.DepthRecog": {"RGBDCamera.DepthRecog": 1.0},
    "MobileBase.Displacement": {"LaserSensor.Scan": 0.5, "MobileBase.Displacement": 0.5},
    "Navigation.AMCL": {"LaserSensor.Scan": 1 / 3, "MobileBase.Displacement": 1 / 3, "Navigation.AMCL": 1 / 3},
    "GlobalRecog.Fusion": {"RGBDCamera.RGBRecog": 0.25, "RGBDCamera.DepthRecog": 0.25, "GlobalRecog.Fusion": 0.5},
}


@pytest.mark.parametrize("behavior", ["NAV", "NAV_HOME", "WAIT", "SPOT", "APPR", "PICK", "PLACE", "BACK"])
@pytest.mark.parametrize("scale", [1.0, 0.5])
def test_every_table_7_6_behavior_composes_from_every_related_service(behavior: str, scale: float) -> None:
    """Eq. 5.1 per behavior of Table 7.5 under Table 7.6 (D70): the services it uses rate 1 (their
    requirements hold); the related ones it does not use count with their published performance."""
    from runtime.missions.composition import behavior_performance

    lab = ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")
    matrix = lab.matrix("turtlebot")
    record = lab.behavior(behavior)
    assert matrix is not None and record is not None
    published = {"LaserSensor.Scan": 0.9, "MobileBase.Displacement": 0.6, "Navigation.AMCL": 0.3,
                 "RGBDCamera.RGBRecog": 0.8, "RGBDCamera.DepthRecog": 0.4, "GlobalRecog.Fusion": 0.7,
                 "RoboticArm.MoveIt": 0.5}  # fmt: skip
    published = {ref: value * scale for ref, value in published.items()}
    used = {u.service for u in record.uses}
    # Used services meet their requirements (sp = 1): samples inside every Require's bounds.
    handles = {}
    for uses in record.uses:
        handles[uses.alias] = compliant(uses)
    related = {ref: KnownService(ref, value) for ref, value in published.items()}
    asked: list[str] = []

    def lookup(ref: str) -> KnownService:
        asked.append(ref)
        return related[ref]

    value = behavior_performance(lab, matrix, record, handles, lookup)
    sp = {ref: 1.0 if ref in used else published[ref] for ref in published}
    expected = sum(sum(w * sp[o] for o, w in TABLE_7_6[ref].items()) for ref in used) / len(used)
    assert value == pytest.approx(expected)
    assert set(asked) == {o for ref in used for o in TABLE_7_6[ref]} - used  # only the related ones
    if scale == 1.0 and behavior == "NAV":
        assert value == pytest.approx((0.9 + 0.6 + 1.0) / 3)  # not 1/3 as when the others counted 0


def test_every_service_at_one_composes_to_one_for_every_behavior_of_table_7_6() -> None:
    from runtime.missions.composition import behavior_performance

    lab = ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")
    matrix = lab.matrix("turtlebot")
    assert matrix is not None
    for behavior in ("NAV", "NAV_HOME", "WAIT", "SPOT", "APPR", "PICK", "PLACE", "BACK"):
        record = lab.behavior(behavior)
        assert record is not None
        handles = {}
        for uses in record.uses:
            handles[uses.alias] = compliant(uses)
        value = behavior_performance(lab, matrix, record, handles, lambda ref: KnownService(ref, 1.0))
        assert value == pytest.approx(1.0), behavior
        silent = behavior_performance(lab, matrix, record, handles, lambda ref: KnownService(ref, 1.0, running=False))
        assert silent is not None and silent <= 1.0
