"""configs/examples/aerial/survey.xml under ckm-run (issue N point 3a; D302): the quadrotor (plan survey)
and the hexarotor (plan survey-hexa) each take off, sweep the Yard with their downward camera
(colour-detection, ground-projection, survey-area over the flight service), confirm the red parcel among
orange, green and blue boxes, signal its map position, fly home and land; the desk agent receives the
payload. The world's own trace (sim-final.json) is the evidence: the parcel's true pose there, the
UAV's flight height and its final rest on its pad."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks.mission_scenarios import object_home
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network

SURVEY = REPO / "configs" / "examples" / "aerial" / "survey.xml"
PLANS = {  # plan: (agent, sim body, its pad's centre and half width)
    "survey": ("quad", "quadrotor", (1.2, 1.5, 0.4)),
    "survey-hexa": ("hexa", "hexarotor", (1.2, 4.5, 0.5)),
}


def tool(name: str) -> str:
    return str(Path(sys.executable).parent / name)


def events(path: Path) -> list[dict[str, object]]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


@pytest.mark.parametrize("plan", sorted(PLANS))
def test_the_uav_finds_the_red_parcel_signals_where_it_is_and_lands_home(tmp_path: Path, plan: str) -> None:
    agent, body, (px, py, half) = PLANS[plan]
    network = private_network()
    run_dir = tmp_path / plan
    done = subprocess.run(
        [tool("ckm-run"), str(SURVEY), "--plan", plan, "--lockstep", "0.01", "--duration", "120", "--log-dir",
         str(run_dir), "--ports", str(network.discovery_port), str(network.base_port)],
        cwd=REPO, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert f"{agent}: mission ended: landed" in done.stdout and "desk: mission ended: received" in done.stdout
    received = [e for e in events(run_dir / "mission-desk.jsonl") if e["kind"] == "signal"]
    assert len(received) == 1, received
    payload = received[0]["value"]["data"]  # type: ignore[index]
    assert (payload["label"], payload["frame"]) == ("red", "map") and payload["reliability"] > 0.5
    assert len(payload["observer"]) == 1  # the UAV's pose it was placed with
    trace = json.loads((run_dir / "sim-final.json").read_text())["trace"]
    parcel = trace[-1]["objects"]["parcel"]
    assert math.dist((payload["x"], payload["y"]), parcel[:2]) < 0.3, (payload, parcel)
    assert abs(payload["z"] - 0.3) < 1e-6  # the box's top, where its blob lies
    others = {n: pose for n, pose in trace[-1]["objects"].items() if n != "parcel"}
    assert len(others) == 5 and all(math.dist((payload["x"], payload["y"]), p[:2]) > 1.5 for p in others.values())
    poses = [sample["bodies"][body] for sample in trace if body in sample.get("bodies", {})]
    assert max(z for _, _, z, *_ in poses) > 2.7  # it searched from the air
    x, y, z = poses[-1][:3]
    assert abs(x - px) <= half and abs(y - py) <= half and z < 0.3, (x, y, z)  # back on its pad
    assert object_home(SURVEY, run_dir, plan) is True  # the plan's own <Expect>s (D306)
    found = [e for e in events(run_dir / f"mission-{agent}.jsonl") if e.get("message") == "object found"]
    assert len(found) == 1 and found[0]["confirmations"] == 3


@pytest.mark.parametrize(
    ("old", "new", "message", "at"),
    [
        ('<Param name="camera" value="quad_camera"/>', "", "give the camera's field of view",
         '<Plugin name="ground" kind="ground-projection">'),
        ('<Param name="mount" value="0.05 0 -0.04 0"/>', '<Param name="mount" value="0.05 0 -0.04"/>',
         "'x y z pitch' or 'x y z roll pitch yaw'", ""),
        ('<Param name="confirmFrames" value="3"/>', '<Param name="confirmFrames" value="three"/>', "confirmFrames",
         ""),
        ('<Param name="area" value="Yard"/>', '<Param name="area" value="Yrd"/>', "is no Area of the map", ""),
        ('<Param name="label" value="red"/>', '<Param name="label" value="purple"/>', "purple", ""),
        ('<Uses service="QuadCamera.Ground" as="detection"/>', '<Uses service="QuadCamera.Detect" as="detection"/>',
         "shares of the image", ""),
        ('    <Uses service="Quad.Flight" as="flight"/>\n    <Uses service="QuadCamera.Ground"',
         '    <Uses service="QuadCamera.Ground"', "flight", '<Behavior name="QUAD_SURVEY"'),
    ],
)
def test_a_mistake_in_the_survey_is_refused_by_ckm_validate_at_its_line(tmp_path: Path, old: str, new: str,
                                                                       message: str, at: str) -> None:
    for name in ("survey.xml", "yard.xml"):
        (tmp_path / name).write_text((SURVEY.parent / name).read_text())
    text = (tmp_path / "survey.xml").read_text()
    assert old in text
    line = text[: text.index(at or old)].count("\n") + 1
    (tmp_path / "survey.xml").write_text(text.replace(old, new, 1))
    done = subprocess.run([tool("ckm-validate"), str(tmp_path / "survey.xml")], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 1, done.stdout + done.stderr
    assert message in done.stdout + done.stderr
    assert f"survey.xml:{line}:" in done.stdout + done.stderr, (line, done.stdout)
