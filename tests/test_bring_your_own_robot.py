"""docs/bring-your-own-robot.md (issue M, point 5): every command of the guide runs as it says, the
scout (a URDF none of CKM's models) does its delivery in the simulation on the standard kinds, and
every mistake the guide lists is refused by ``ckm-validate`` at its line."""

from __future__ import annotations

import json
import math
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO
from tests.runtime.network.conftest import private_network

GUIDE = REPO / "docs" / "bring-your-own-robot.md"
BYOR = REPO / "configs" / "examples" / "byor"
SET_UP = ("bash scripts/setup.sh", "source .venv/bin/activate")  # what the test command has already done
CHECKS = (
    "ckm-plugins show hardware.sim",
    "ckm-validate configs/examples/byor/world.xml",
    "ckm-validate configs/examples/byor/robot.xml",
    "ckm-plugins interfaces",
    "ckm-plugins show plugin.laser-scan",
    "ckm-plugins show plugin.base-displacement",
    "ckm-plugins show plugin.amcl-navigation",
    "ckm-validate configs/examples/byor/services.xml",
    "ckm-plugins show behavior.navigate-to",
    "ckm-validate configs/examples/byor/scout.xml",
    "ckm-mission validate configs/examples/byor/scout.xml",
)
HARDWARE_RUN = "ckm-run configs/examples/byor/robot.xml --lockstep 0.01 --duration 5 --log-dir runs/scout-hardware"
MISSION_RUN = (
    "ckm-run configs/examples/byor/scout.xml --plan delivery --lockstep 0.01 --duration 300 "
    "--log-dir runs/scout --record /nav/pose,/nav/status,/sim/scout/pose"
)
REPORT = "ckm-mission report runs/scout --html --config configs/examples/byor/scout.xml"
PALLET = (6.6, 7.4, 3.7, 4.3)  # world.xml: the pallet's outline, xmin xmax ymin ymax
DOCK_AREA = (0.2, 1.8, 0.2, 1.8)


def guide_commands() -> list[str]:
    """The commands of the guide's console blocks, in order."""
    return [line[2:].strip() for line in GUIDE.read_text().splitlines() if line.startswith("$ ")]


def command(text: str, run_dir: Path | None = None) -> list[str]:
    """``text`` as the venv runs it; a run moved to ``run_dir`` and onto private network ports."""
    words = shlex.split(text)
    program = str(Path(sys.executable).parent / words[0])
    args = words[1:]
    if run_dir is not None and words[0] == "ckm-run":
        args[args.index("--log-dir") + 1] = str(run_dir)
        network = private_network()
        args += ["--ports", str(network.discovery_port), str(network.base_port)]
    elif run_dir is not None:
        args[args.index("runs/scout")] = str(run_dir)
    return [program, *args]


def run(text: str, run_dir: Path | None = None, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(command(text, run_dir), cwd=REPO, capture_output=True, text=True, timeout=timeout)


def test_the_guide_shows_exactly_the_commands_tested_here() -> None:
    assert guide_commands() == [*SET_UP, *CHECKS[:3], HARDWARE_RUN, *CHECKS[3:], MISSION_RUN, REPORT]


@pytest.mark.parametrize("text", CHECKS)
def test_each_check_of_the_guide_passes(text: str) -> None:
    done = run(text)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert "Traceback" not in done.stderr


def test_the_hardware_alone_runs_its_loops_without_a_missed_deadline(tmp_path: Path) -> None:
    done = run(HARDWARE_RUN, tmp_path / "hardware")
    assert done.returncode == 0, done.stderr[-2000:]
    tasks = json.loads((tmp_path / "hardware" / "stats.json").read_text())["nodes"]["scout_base"]["tasks"]
    assert tasks["scout_base.left_pid"]["releases"] >= 490  # 100 Hz for 5 simulated seconds
    assert all(task["misses"] == 0 for task in tasks.values())


def _outline_distance(x: float, y: float, box: tuple[float, float, float, float]) -> float:
    xmin, xmax, ymin, ymax = box
    return math.hypot(max(xmin - x, 0.0, x - xmax), max(ymin - y, 0.0, y - ymax))


def test_the_scout_fetches_from_the_pallet_and_docks_by_the_worlds_own_record(tmp_path: Path) -> None:
    """The world's trace (sim-final.json), not the mission's word: the scout stood short of the
    pallet's outline facing it, then ended in DockArea; the report lists no problem."""
    run_dir = tmp_path / "scout"
    done = run(MISSION_RUN, run_dir, timeout=400)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert "scout: mission ended: delivered" in done.stdout
    events = [json.loads(line) for line in (run_dir / "mission-scout.jsonl").read_text().splitlines()]
    arrived = next(e["t"] for e in events if e["kind"] == "exit" and e["state"] == "TO_PALLET")
    trace = json.loads((run_dir / "sim-final.json").read_text())["trace"]
    at_pallet = [s["robots"]["scout"] for s in trace if s["time"] <= arrived][-1]  # the world's sample before
    assert 0.2 < _outline_distance(at_pallet[0], at_pallet[1], PALLET) < 0.6
    facing = math.atan2(4.0 - at_pallet[1], 7.0 - at_pallet[0])
    assert abs(math.remainder(at_pallet[2] - facing, math.tau)) < 0.35
    x, y, _ = trace[-1]["robots"]["scout"]
    assert _outline_distance(x, y, DOCK_AREA) == 0.0
    report = run(REPORT, run_dir)
    assert report.returncode == 0, report.stderr[-2000:]
    text = re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", (run_dir / "report.html").read_text()))
    assert "Problems 0 in 0 kind(s)" in text


MISTAKES = (  # file, text, replaced by, the line it is refused at, what ckm-validate says
    ("services.xml", '      <Param name="robotRadius" value="0.29"/>\n', "", 58, "needs parameter 'robotRadius'"),
    ("services.xml", 'value="world.xml"', 'value="wrld.xml"', 59, "no such file"),
    ("services.xml", 'value="world.xml"', 'value="robot.xml"', 59, "robot.xml holds no <Environment>"),
    ("mission.xml", 'value="pallet"', 'value="palet"', 14, "did you mean 'pallet'?"),
    (
        "services.xml",
        '<Input name="odom" topic="/base/odom"/>',
        '<Input name="odometry" topic="/base/odom"/>',
        72,
        "reads no Input 'odometry' (it reads: scan, odom)",
    ),
    ("mission.xml", 'as="nav">', 'as="navigation">', 15, "its kind reads a navigation service as 'nav'"),
    (
        "robot.xml",
        '      <Param name="ticksPerRev" value="2048"/>\n',
        "",
        16,
        "a wheel encoder (counter in, joint) needs Param 'ticksPerRev'",
    ),
    ("services.xml", '      <Param name="fov" value="3.4907"/>\n', "", 23, "needs parameter 'fov'"),
    (
        "robot.xml",
        '      <Param name="fov" value="3.4907"/>\n',
        "",
        130,
        "a lidar needs its field of view: Param 'fov'",
    ),
    (
        "robot.xml",
        'min="0" max="8" size="541"',
        'min="0" size="541"',
        130,
        "a lidar needs its range: the HWChannel's max (m)",
    ),
    ("robot.xml", 'value="lidar_link"', 'value="lidar_lnk"', 132,
     "Param 'link': the model scout.urdf has no link 'lidar_lnk'; did you mean lidar_link"),
    ("robot.xml", '<Param name="pose" value="1.0 1.0 0"/>', '<Param name="pose" value="7.0 4.0 0"/>', 20,
     "Param 'pose' places the robot at (7, 4), inside 'pallet'"),
)


@pytest.mark.parametrize(("name", "old", "new", "line", "message"), MISTAKES)
def test_each_mistake_of_the_guide_is_refused_at_its_line(
    tmp_path: Path, name: str, old: str, new: str, line: int, message: str
) -> None:
    copy = tmp_path / "byor"
    shutil.copytree(BYOR, copy)
    text = (copy / name).read_text()
    assert old in text
    (copy / name).write_text(text.replace(old, new, 1))
    done = subprocess.run(
        [str(Path(sys.executable).parent / "ckm-validate"), str(copy / "scout.xml")],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 1
    assert re.search(rf"{re.escape(str(copy / name))}:{line}:\d+: .*{re.escape(message)}", done.stdout + done.stderr), (
        done.stdout + done.stderr
    )
