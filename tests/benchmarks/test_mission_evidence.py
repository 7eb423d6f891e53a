"""The world's own evidence a plan declares (``<Expect>``, D300), judged from a hand-written ``sim-final.json``."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

import ckmconf
from benchmarks.mission_scenarios import evidence, object_home

LAB = Path("configs/usecase/lab.xml")


def _final(run_dir: Path, position: list[float]) -> None:
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "sim-final.json").write_text(json.dumps({"positions": {"cylinder_red_stripes": position}}))


def test_the_target_on_the_drop_table_is_met(tmp_path: Path) -> None:
    _final(tmp_path, [1.05, 1.95, 0.36])  # the drop table's centre is (1.0, 1.9), its top at 0.30 m
    assert object_home(LAB, tmp_path, "cooperative") is True
    [judged] = evidence(LAB, "individual", {"positions": {"cylinder_red_stripes": [1.05, 1.95, 0.36]}})
    assert judged["met"] is True and judged["on"] == "drop_table"


@pytest.mark.parametrize("position", [[7.6, 6.1, 0.36], [1.05, 1.95, 0.03]])  # still on the workbench; on the floor
def test_the_target_elsewhere_is_not_met(tmp_path: Path, position: list[float]) -> None:
    _final(tmp_path, position)
    assert object_home(LAB, tmp_path, "cooperative") is False


def test_a_final_record_without_the_object_is_unknown(tmp_path: Path) -> None:
    tmp_path.mkdir(exist_ok=True)
    (tmp_path / "sim-final.json").write_text(json.dumps({"positions": {}}))
    assert object_home(LAB, tmp_path, "cooperative") is None


def test_an_unknown_expect_object_is_refused_at_its_line(tmp_path: Path) -> None:
    copy = tmp_path / "usecase"
    shutil.copytree(LAB.parent, copy)
    plan = copy / "plan.xml"
    text = plan.read_text().replace('Expect object="cylinder_red_stripes"', 'Expect object="cylinder_red_strips"', 1)
    plan.write_text(text)
    line = next(i for i, row in enumerate(text.splitlines(), 1) if "cylinder_red_strips" in row)
    with pytest.raises(ckmconf.ConfigError) as raised:
        ckmconf.load(copy / "lab.xml")
    assert f"plan.xml:{line}:" in str(raised.value)
    assert "object 'cylinder_red_strips' does not exist in the environment" in str(raised.value)



AERIAL = Path("configs/examples/aerial/uavs.xml")
AWAY = {"quadrotor": [8.55, 2.05, 0.06, 0.0, 0.0, 0.1], "hexarotor": [8.4, 4.3, 0.07, 0.0, 0.0, -0.2]}
"""The airframes' final base poses (x, y, z, roll, pitch, yaw) on their away pads."""


def test_robots_expected_on_their_pads_are_judged_by_their_final_body_poses() -> None:
    judged = evidence(AERIAL, "cross", {"positions": {}, "bodies": AWAY})
    assert [(e["object"], e["on"], e["met"]) for e in judged] == [
        ("quadrotor", "pad_quad_away", True), ("hexarotor", "pad_hexa_away", True)]
    assert judged[0]["position"] == AWAY["quadrotor"][:3]
    stayed = AWAY | {"hexarotor": [1.5, 4.2, 0.07, 0.0, 0.0, 0.0]}  # still on its home pad
    assert [e["met"] for e in evidence(AERIAL, "cross", {"positions": {}, "bodies": stayed})] == [True, False]
    assert [e["met"] for e in evidence(AERIAL, "cross", {"positions": {}})] == [None, None]  # a record without bodies


def test_an_unknown_robot_is_refused_at_its_line_naming_the_robots(tmp_path: Path) -> None:
    copy = tmp_path / "aerial"
    shutil.copytree(AERIAL.parent, copy)
    path = copy / AERIAL.name
    text = path.read_text().replace('Expect object="quadrotor"', 'Expect object="quadrotr"', 1)
    path.write_text(text)
    line = next(i for i, row in enumerate(text.splitlines(), 1) if "quadrotr\"" in row)
    with pytest.raises(ckmconf.ConfigError) as raised:
        ckmconf.load(path)
    message = str(raised.value)
    assert f"uavs.xml:{line}:" in message
    assert "object 'quadrotr' does not exist in the environment or the simulated robots; did you mean 'quadrotor'?" \
        in message
