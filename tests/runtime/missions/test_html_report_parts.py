"""The pieces of the HTML run report: payload shapes read from bags, frames, problems, reference rows."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
from ckm_lab.table_7_9 import TABLE_7_9
from matplotlib.image import imread

from ckmconf.model.environment import ZoomMap
from runtime.missions.recording import RunRecorder, read_run
from runtime.missions.report import AgentReport, StateRow
from runtime.missions.report_bag import find_bags, image_pixels, pose_xy, pose_yaw, sightings
from runtime.missions.report_figures import image_png
from runtime.missions.report_problems import collect
from runtime.missions.report_references import ReferenceRow, ReferenceTable, compare, installed_tables
from runtime.missions.report_views import replay_zoom


def test_pose_shapes_of_ckm_and_ros_messages() -> None:
    assert pose_xy({"x": 1.0, "y": 2.0, "yaw": 0.0}) == (1.0, 2.0)  # Pose2D
    assert pose_xy({"stamp": 3.0, "pose": {"x": 1.0, "y": 2.0}, "dispersion": 0.1}) == (1.0, 2.0)  # PoseEstimate
    stamped = {"header": {}, "pose": {"position": {"x": 4.0, "y": 5.0, "z": 0.0}, "orientation": {}}}
    assert pose_xy(stamped) == (4.0, 5.0)  # geometry_msgs/PoseStamped
    odometry = {"pose": {"pose": {"position": {"x": 6.0, "y": 7.0}}, "covariance": np.zeros(36)}}
    assert pose_xy(odometry) == (6.0, 7.0)  # nav_msgs/Odometry
    assert pose_xy({"x": float("nan"), "y": 1.0}) is None and pose_xy([1, 2]) is None
    assert pose_yaw({"stamp": 3.0, "pose": {"x": 1.0, "y": 2.0, "yaw": 0.5}}) == 0.5
    quarter = {"x": 0.0, "y": 0.0, "z": np.sin(np.pi / 4), "w": np.cos(np.pi / 4)}  # 90° about z
    assert pose_yaw({"pose": {"position": {"x": 0.0, "y": 0.0}, "orientation": quarter}}) == pytest.approx(np.pi / 2)
    assert pose_yaw(odometry) is None and pose_yaw({"yaw": 1.0}) is None  # no orientation; a yaw without a place


def test_sightings_name_an_object_by_every_word_it_has() -> None:
    cylinder = {"name": "cyl_1", "shape": "cylinder", "texture": "red_stripes", "reliability": 0.9, "x": None}
    result = {"objects": [cylinder, {"label": "box", "shape": "box", "reliability": True}, "junk"]}
    (seen,) = sightings(result, 2.0)
    assert (seen.name, seen.reliability, seen.x, seen.time) == ("cyl_1 cylinder red_stripes", 0.9, None, 2.0)
    assert sightings({"objects": "none"}, 0.0) == [] and sightings(None, 0.0) == []


def test_image_payloads_become_pngs() -> None:
    bgr = np.zeros((2, 3, 3), dtype=np.uint8)
    bgr[..., 0] = 255  # blue in bgr8
    pixels = image_pixels({"width": 3, "height": 2, "encoding": "bgr8", "data": bgr.tobytes()})
    assert pixels.shape == (2, 3, 3) and pixels[0, 0].tolist() == [0, 0, 255]
    depth = np.array([[0, 1000], [2000, 4000]], dtype=np.uint16)
    decoded = imread(io.BytesIO(image_png(depth)), format="png")
    assert decoded[0, 0, 0] == 0.0 and decoded[1, 1, 0] == 1.0  # scaled to its own range
    wide = imread(io.BytesIO(image_png(np.zeros((480, 1280, 3), dtype=np.uint8))), format="png")
    assert wide.shape[1] <= 480
    with pytest.raises(ValueError, match="do not hold it"):
        image_pixels({"width": 30, "height": 2, "encoding": "rgb8", "data": b"\0" * 10})
    with pytest.raises(ValueError, match="encoding 'yuv422'"):
        image_pixels({"width": 1, "height": 1, "encoding": "yuv422", "data": b"\0\0"})


def test_bags_are_found_up_to_two_levels_below_the_run(tmp_path: Path) -> None:
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "metadata.yaml").write_text("")
    (tmp_path / "nodes" / "remote_pc").mkdir(parents=True)
    (tmp_path / "nodes" / "remote_pc" / "topics.mcap").write_bytes(b"")
    (tmp_path / "report").mkdir()
    assert find_bags(tmp_path) == [tmp_path / "bag", tmp_path / "nodes" / "remote_pc"]


def test_task_failures_and_misses_count_from_the_statistics(tmp_path: Path) -> None:
    with RunRecorder(tmp_path, "a") as rec:
        rec.write("start", mission="M")
    stats: dict[str, object] = {
        "nodes": {"n": {"tasks": {"n.loop": {"failures": 3, "misses": 7, "first_failure": "ZeroDivisionError"}}}}
    }
    topics = {"/scan": {"written": 5, "dropped": 2, "firstDrop": "ranges: not a float32[]"}, "/x": {"dropped": 0}}
    stats["recording"] = {"bag": "run/bag", "failure": "disk full", "topics": topics}
    (tmp_path / "stats.json").write_text(json.dumps(stats))
    (tmp_path / "part").mkdir()
    (tmp_path / "part" / "ckm.log").write_text("2026-01-01 00:00:00,000 CRITICAL ckm.part: out of memory\n")
    found = {(p.source, p.what): p for p in collect(tmp_path, read_run(tmp_path)).problems}
    assert found[("stats.json", "task n.loop: failures")].count == 3
    assert found[("stats.json", "task n.loop: misses")].count == 7
    assert found[("part/ckm.log", "ckm.part: out of memory")].severity == "critical"
    assert found[("stats.json", "recording: samples of /scan dropped")].count == 2
    assert found[("stats.json", "recording into run/bag failed")].example == "disk full"
    assert not [what for _, what in found if "/x" in what]
    assert found[("recording", "a: the recording ends without an end event (crashed or killed)")].count == 1


def test_thesis_rows_match_our_states_per_visit() -> None:
    expected = ["NAVIGATION", "SPOT", "APPR-PICK", "PLACE-BACK", "SPOT_TRACK", "SPOT_FIX"]
    assert [r.state for r in TABLE_7_9.rows] == expected
    rows = [StateRow("a", f"M/{label}", label.rsplit("/", 1)[-1], [t], [t / 100], p) for label, t, p in (
        ("Navigation/NAV", 10.0, 1.0), ("Navigation/WAIT", 30.0, 0.5), ("ObjectPlace/NAV", 20.0, None))]  # fmt: skip
    (navigation,) = compare(TABLE_7_9, AgentReport("a", "M", None, 100.0, "ok", rows))
    assert navigation.times == (40.0, 20.0) and navigation.contributions == (0.4, 0.2)
    assert navigation.performance == pytest.approx((10 * 1.0 + 30 * 0.5) / 40)
    (going,) = compare(TABLE_7_9, AgentReport("a", "M", None, 100.0, None, rows[:2]))
    assert going.times == (40.0,)  # the return visit never made is left out, not shown as 0 s


def test_a_reference_table_about_another_system_shows_nothing_for_the_lab() -> None:
    """A published row stands only for the states its patterns name: a depot's table matches none of
    the lab's rows, and the depot's own states are compared with it."""
    depot = ReferenceTable("depot release 1", (ReferenceRow("DRIVE", (12.0,), (0.5,), 0.9, (("Delivery/GO*",),)),))
    lab = [StateRow("a", "M/Navigation/NAV", "NAV", [10.0], [0.1], 1.0)]
    assert compare(depot, AgentReport("a", "M", None, 100.0, "ok", lab)) == []
    own = [StateRow("a", "Depot/Delivery/GO_PALLET", "GO_PALLET", [8.0], [0.4], 0.8)]
    (drive,) = compare(depot, AgentReport("a", "Delivery", None, 20.0, "ok", own))
    assert drive.times == (8.0,) and drive.rows == ("Delivery/GO_PALLET",) and drive.performance == 0.8


def test_the_lab_package_registers_table_7_9_as_a_reference_table() -> None:
    tables, problems = installed_tables()
    assert problems == []
    assert TABLE_7_9 in tables and TABLE_7_9.source == "thesis Table 7.9 (§7.5.2, p. 132)"


def test_zoom_map_areas_are_replayed_with_the_border_and_timeout_triggers() -> None:
    settings = ZoomMap(width=4.0, depth=2.0, border=0.1, timeout=10.0)
    driving = [(t * 0.25, t * 0.25, 0.0) for t in range(17)]  # 1 m/s along x for 4 s
    assert [a[:3] for a in replay_zoom(driving, settings)] == [(0.0, 0.0, 0.0), (1.75, 1.75, 0.0), (3.5, 3.5, 0.0)]
    sideways = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.75), (2.0, 0.0, 0.85)]  # 0.2 m of the 2 m depth is the border
    assert [a[0] for a in replay_zoom(sideways, settings)] == [0.0, 2.0]
    standing = [(float(t), 5.0, 5.0) for t in range(25)]
    assert replay_zoom(standing, settings) == [(t, 5.0, 5.0, 4.0, 2.0) for t in (0.0, 10.0, 20.0)]
