"""configs/examples/aerial/uavs.xml under ckm-run: a quadrotor and a hexarotor, each flown by the
flight library (controller.twist-axes, plugin.flight-control, take-off / fly-to / land) through its
simulated airframe's channels, take off, cross the 2.2 m rack and land on the away pads. The world's
own trace (sim-final.json) is the evidence, not the missions' word."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks.mission_scenarios import object_home
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network

UAVS = REPO / "configs" / "examples" / "aerial" / "uavs.xml"
RACK = (4.6, 5.4, 2.2)  # hall.xml: the rack's x span and height
PADS = {"quadrotor": (8.5, 2.0, 0.4), "hexarotor": (8.5, 4.2, 0.5)}  # away pads: centre and half width


def tool(name: str) -> str:
    return str(Path(sys.executable).parent / name)


def test_both_uavs_cross_the_rack_above_it_and_land_on_their_away_pads(tmp_path: Path) -> None:
    network = private_network()
    run_dir = tmp_path / "cross"
    done = subprocess.run(
        [tool("ckm-run"), str(UAVS), "--plan", "cross", "--lockstep", "0.01", "--duration", "120", "--log-dir",
         str(run_dir), "--ports", str(network.discovery_port), str(network.base_port)],
        cwd=REPO, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert "quad: mission ended: landed" in done.stdout and "hexa: mission ended: landed" in done.stdout
    trace = json.loads((run_dir / "sim-final.json").read_text())["trace"]
    for body, (px, py, half) in PADS.items():
        poses = [sample["bodies"][body] for sample in trace if body in sample.get("bodies", {})]
        over_rack = [z for x, _, z, *_ in poses if RACK[0] - 0.3 <= x <= RACK[1] + 0.3]
        assert over_rack and min(over_rack) > RACK[2] + 0.5, (body, over_rack)  # well above it, never through
        x, y, z = poses[-1][:3]
        assert abs(x - px) <= half and abs(y - py) <= half, (body, x, y)  # on its pad
        assert z < 0.3, (body, z)  # resting on its skids
        assert abs(poses[-1][3]) < 0.05 and abs(poses[-1][4]) < 0.05  # level: roll, pitch
    assert object_home(UAVS, run_dir, "cross") is True  # the plan's own <Expect>s, from the final bodies (D306)
    report = subprocess.run([tool("ckm-mission"), "report", str(run_dir), "--html", "--config", str(UAVS)],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert report.returncode == 0, report.stderr[-2000:]
    text = re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", (run_dir / "report.html").read_text()))
    assert "Problems 0 in 0 kind(s)" in text
    assert re.search(r"quad QuadCross success \(landed\)", text) and re.search(r"hexa HexaCross success", text)


@pytest.mark.parametrize(
    ("old", "new", "message", "at"),
    [
        ('<Param name="radius" value="0.3"/>', "", "needs parameter 'radius'", '<Param name="environment"'),
        ('<Param name="goal" value="8.5 2.0 3.0"/>', '<Param name="goal" value="8.5 2.0"/>',
         "is not 'x y z' or 'x y z yaw'", ""),
        ('<Param name="maxThrust" value="6.0"/>', '<Param name="maxThrust" value="2.0"/>', "cannot lift", ""),
        ('<Param name="axis" value="vz"/>', '<Param name="axis" value="up"/>', "axis", ""),
    ],
)
def test_a_mistake_in_the_example_is_refused_by_ckm_validate_at_its_line(tmp_path: Path, old: str, new: str,
                                                                        message: str, at: str) -> None:
    for name in ("uavs.xml", "hall.xml"):
        (tmp_path / name).write_text((UAVS.parent / name).read_text())
    text = (tmp_path / "uavs.xml").read_text()
    assert old in text
    line = text[: text.index(at or old)].count("\n") + 1
    (tmp_path / "uavs.xml").write_text(text.replace(old, new, 1))
    done = subprocess.run([tool("ckm-validate"), str(tmp_path / "uavs.xml")], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 1, done.stdout + done.stderr
    assert message in done.stdout + done.stderr
    assert f"uavs.xml:{line}:" in done.stdout + done.stderr
