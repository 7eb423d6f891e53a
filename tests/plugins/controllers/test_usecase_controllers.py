"""Every Controller and Optional part of the use case's nodes (configs/usecase/nodes.xml) builds from
its element with the registered kind, and each new kind takes one period of plausible inputs."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

import ckmconf
from ckmconf.model import System
from plugins.controllers.multi import MultiOutputController
from runtime.kernel.interfaces import Controller
from runtime.registry import default_registry
from tests.conftest import REPO

INPUTS: dict[str, dict[str, Any]] = {
    "diffdrive": {"setpoint": {"linear": 0.3, "angular": 0.5}},
    "hold_still": {"measure[0]": 0.2, "measure[1]": 0.3},
    "odometry": {"measure[0]": 0.2, "measure[1]": 0.3},
    "arm_trajectory": {"measure": [0.0] * 5, "setpoint": {"joint_names": [], "points": []}},
    "head_control": {"measure[0]": 0.0, "measure[1]": 0.0, "setpoint": {"pan": 0.5, "tilt": -0.2}},
}


@pytest.fixture(scope="module")
def system() -> System:
    return ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")


def build(system: System) -> dict[str, Controller]:
    registry, built = default_registry(), {}
    for node in system.nodes:
        for record in node.controllers:
            built[record.name] = registry.resolve("controller", record.kind, record)(record)
            if record.optional is not None:
                part = record.optional
                derived = dataclasses.replace(
                    record, name=f"{record.name}.optional", kind=part.kind, params=part.params, optional=None
                )
                built[derived.name] = registry.resolve("controller", part.kind, part)(derived)
    return built


def test_every_controller_of_the_use_case_builds(system: System) -> None:
    built = build(system)
    assert {name: type(c).__name__ for name, c in built.items() if name in INPUTS or "optional" in name} == {
        "diffdrive": "DiffDrive",
        "hold_still": "RampStop",
        "left_pid.optional": "FrictionFeedforward",
        "right_pid.optional": "FrictionFeedforward",
        "odometry": "DiffDriveOdometry",
        "arm_trajectory": "JointTrajectory",
        "head_control": "PanTiltPosition",
    }


def test_each_new_kind_steps_with_one_value_per_output(system: System) -> None:
    built = build(system)
    for name, inputs in INPUTS.items():
        controller = built[name]
        assert isinstance(controller, MultiOutputController)
        row = controller.step_outputs(inputs, controller.record.period)
        assert len(row) == len(controller.record.outputs), name
    # The use case's <Optional> repeats the required PID's gains (kp 1.2, ki 6.0, kd 0.01 on the measure)
    # and adds 'coulomb' 0.02: error 0.1 gives 1.2·0.1 + 6.0·0.1·0.01 + 0.02 on the first step.
    expected = 1.2 * 0.1 + 6.0 * 0.1 * 0.01 + 0.02
    assert built["left_pid.optional"].step({"measure": 0.1, "setpoint": 0.2}, 0.01) == pytest.approx(expected)
