"""Camera snapshots end to end (issue K point 2, D197): a simulated Turtlebot runs a short mission
with its camera recorded sparsely (``--record /camera/rgb/image_raw@0.5:jpeg``), the bag is checked
by the independent readers (``ckm-bag check``), and the HTML report shows the frame nearest each
state's entry and end; the same run reported without its camera topic says so and still reports.

The run uses configs/examples/sim_ros_types.xml with a private <Network> on 127.0.0.1 and a plan of
timer states (NAV → SPOT → PICK → PLACE) added, so the agent's moments come from a real run.
"""

from __future__ import annotations

import base64
import io
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image as PilImage
from rosbags.rosbag2 import Reader

from runtime.missions.html_report import Options, build_html
from runtime.missions.report_bag import ReportTopics
from tests.conftest import REPO
from tests.runtime.missions.test_html_report import parse
from tests.runtime.network.conftest import private_network

EXAMPLE = REPO / "configs" / "examples" / "sim_ros_types.xml"
CAMERA = "/camera/rgb/image_raw"
MISSION = """
  <Behavior name="NAV" kind="timer"><Param name="duration" value="1.2"/></Behavior>
  <Behavior name="SPOT" kind="timer"><Param name="duration" value="1.2"/></Behavior>
  <Behavior name="PICK" kind="timer"><Param name="duration" value="1.2"/></Behavior>
  <Behavior name="PLACE" kind="timer"><Param name="duration" value="1.2"/></Behavior>
  <Mission name="Fetch" initial="NAV">
    <State name="NAV" behavior="NAV"/>
    <State name="SPOT" behavior="SPOT"/>
    <State name="PICK" behavior="PICK"/>
    <State name="PLACE" behavior="PLACE"/>
    <Final name="done"/>
    <Transition from="NAV" to="SPOT"/>
    <Transition from="SPOT" to="PICK"/>
    <Transition from="PICK" to="PLACE"/>
    <Transition from="PLACE" to="done"/>
  </Mission>
  <Plan name="fetch">
    <Agent name="turtlebot" node="turtlebot" mission="Fetch"/>
  </Plan>
"""


def _config(tmp_path: Path) -> Path:
    """sim_ros_types.xml on a private network, with the plan of timer states."""
    net = private_network()
    element = f'<Network group="{net.group}" discoveryPort="{net.discovery_port}" basePort="{net.base_port}"/>'
    text = re.sub(r"(<System [^>]*>)", lambda m: m.group(1) + "\n  " + element, EXAMPLE.read_text(), count=1)
    copy = tmp_path / "sim_camera_mission.xml"
    assert text.count("  <Environment ") == 1
    copy.write_text(text.replace("  <Environment ", MISSION + "  <Environment "))
    return copy


def _run(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=timeout, cwd=REPO)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One recorded run: the plan's mission, the camera at most every 2 s as JPEG, the odometry whole."""
    tmp = tmp_path_factory.mktemp("snapshots")
    run = tmp / "run"
    record = f"{CAMERA}@0.5:jpeg,/odom"
    done = _run("-m", "runtime.cli", str(_config(tmp)), "--plan", "fetch", "--duration", "7", "--log-dir", str(run),
                "--record", record, "--record-format", "mcap+sqlite3")  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    return run


@pytest.mark.timeout(180)
def test_the_camera_is_recorded_at_the_limited_rate_as_compressed_images(run_dir: Path) -> None:
    recording = json.loads((run_dir / "stats.json").read_text())["recording"]
    camera = recording["topics"][CAMERA]
    assert camera["bagTopic"] == CAMERA + "/compressed" and camera["rosType"] == "sensor_msgs/msg/CompressedImage"
    assert camera["maxRate"] == 0.5 and camera["compression"] == "jpeg" and camera["dropped"] == 0
    assert camera["written"] >= 2 and camera["throttled"] >= 2 * camera["written"]  # the camera grabs at 2 Hz
    assert recording["topics"]["/odom"]["throttled"] == 0  # no limit asked
    stamps, sizes = [], []
    with Reader(run_dir / "bag") as reader:
        wanted = [c for c in reader.connections if c.topic == CAMERA + "/compressed"]
        for _, stamp, data in reader.messages(connections=wanted):
            stamps.append(stamp * 1e-9)
            sizes.append(len(data))
    assert len(stamps) == camera["written"]
    assert min(np.diff(stamps)) >= 2.0 - 0.01  # at most one frame every 2 s of the run's clock
    assert max(sizes) < 57600  # the raw 160×120 rgb8 frame is 57600 bytes: JPEG is smaller
    checked = _run("-m", "runtime.ros.bag_cli", "check", "--json", str(run_dir))
    assert checked.returncode == 0, checked.stdout + checked.stderr
    for line in checked.stdout.splitlines():
        result = json.loads(line)
        assert result["ok"] and result["topics"][CAMERA + "/compressed"]["decoded"] == camera["written"]


@pytest.mark.timeout(180)
def test_the_report_shows_the_frames_nearest_each_state_of_the_agent(run_dir: Path) -> None:
    page = parse(build_html(run_dir, Options(topics=ReportTopics(cameras=(CAMERA,))))[0])
    rows = page.table("snapshots agent-turtlebot")
    cells = [cell for row in rows for cell in row]
    entered = [c for c in cells if " entered at " in c]
    assert [c.split()[0] for c in entered] == ["NAV", "SPOT", "PICK", "PLACE"]
    assert len([c for c in cells if " ended at " in c]) == 4  # every state ended by its transition
    shown = [c for c in cells if "from it" in c]
    assert len(shown) >= 6  # a frame every 2 s: within 1 s of most moments, none further than 5 s
    offsets = [float(re.search(r"frame ([+-][0-9.]+) s from it", c)[1]) for c in shown]  # type: ignore[index]
    assert all(abs(o) <= 5.0 for o in offsets)
    jpegs = [(alt, src) for alt, src in page.images if src.startswith("data:image/jpeg;base64,")]
    assert len(jpegs) == len(shown) and all(alt.startswith("turtlebot Fetch/") for alt, _ in jpegs)
    with PilImage.open(io.BytesIO(base64.b64decode(jpegs[0][1].split(",", 1)[1]))) as picture:
        assert picture.format == "JPEG" and picture.size == (160, 120)  # the camera's frame, as recorded


@pytest.mark.timeout(180)
def test_a_run_without_camera_frames_still_reports_and_says_so(run_dir: Path) -> None:
    text, errors = build_html(run_dir, Options(topics=ReportTopics(cameras=("/nao/camera/image",))))
    assert errors == []
    page = parse(text)
    assert any(n.startswith("No camera frames: topic /nao/camera/image: none of them in the bag") for n in page.notes)
    assert not [t for t, _ in page.tables if "snapshots" in t]
    assert "Fig. 7.23 turtlebot" in {alt for alt, _ in page.images} or page.images  # the rest of the report is there
