"""Service states and the Services Performance Composition of eq. 5.1 on Table 7.6 (D13)."""

from __future__ import annotations

from pathlib import Path

import pytest

import ckmconf
from ckmconf.model.missions import CompositionMatrix, MatrixService, Require, Row
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
