"""The HTML report's world rows (D178, D199): the scenario and the disturbances the world server
fired (records made by plugins.sim.disturbances.Fired, as the server writes them), a killed server's
sim-disturbances.json, an undisturbed world, an unreadable file; and a camera frame too far from its
moment is not shown as of it (D198)."""

from __future__ import annotations

import json
from pathlib import Path

from plugins.sim.disturbances import Fired
from runtime.missions.html_report import build_html
from runtime.missions.report_bag import BagData, Frame, Moment, ReportTopics
from runtime.missions.report_snapshots import MAX_FRAME_GAP, agent_cameras, snapshots_section
from runtime.missions.report_world import world_rows
from tests.runtime.missions.test_html_report import make_run, parse

MOVED = Fired(31.25, 3, "move target_cylinder by 0.3 0 when turtlebot within 0.45 of target_cylinder",
              "target_cylinder", [2.1, 3.4, 0.36])  # fmt: skip
ADDED = Fired(12.0, 1, "add box crate 0.4 0.4 0.5 at 1.5 2.0", "crate", [1.5, 2.0, 0.25])


def _final(run_dir: Path, scenario: str | None, fired: list[Fired]) -> None:
    final = {"time": 120.0, "positions": {"target_cylinder": [2.1, 3.4, 0.36]}, "scenario": scenario,
             "disturbances": [f.to_dict() for f in fired], "trace": []}  # fmt: skip
    (run_dir / "sim-final.json").write_text(json.dumps(final))


def test_the_scenario_and_each_fired_disturbance_are_named(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run", bag=False)
    _final(run_dir, "benchmarks/scenarios/moved-object.txt", [ADDED, MOVED])
    summary = {row[0]: row[1] for row in parse(build_html(run_dir)[0]).table("summary")}
    assert summary["World at the end"] == "target_cylinder (2.10, 3.40, 0.36)"
    assert summary["World scenario"] == "moved-object (benchmarks/scenarios/moved-object.txt)"
    assert summary["Disturbances"] == (
        "2 fired:at 12.0 s (scenario line 1): add box crate 0.4 0.4 0.5 at 1.5 2.0; crate left at (1.50, 2.00, 0.25)"
        "at 31.2 s (scenario line 3): move target_cylinder by 0.3 0 when turtlebot within 0.45 of target_cylinder; "
        "target_cylinder left at (2.10, 3.40, 0.36)"
    )


def test_an_undisturbed_world_a_killed_server_and_a_broken_file_say_so(tmp_path: Path) -> None:
    assert world_rows(tmp_path) == [["World at the end", "no simulated world (no sim-final.json)"]]
    _final(tmp_path, None, [])
    assert world_rows(tmp_path)[1:] == [
        ["World scenario", "none: the world was not disturbed"],
        ["Disturbances", "none fired"],
    ]
    (tmp_path / "sim-final.json").unlink()  # the server was killed: only what it wrote as events fired
    (tmp_path / "sim-disturbances.json").write_text(json.dumps([MOVED.to_dict()]))
    rows = dict(world_rows(tmp_path))
    assert rows["World at the end"] == "unknown (no sim-final.json)"
    assert rows["World scenario"].startswith("unknown (no sim-final.json")
    assert rows["Disturbances"].startswith("1 fired:<br>at 31.2 s (scenario line 3): move target_cylinder")
    (tmp_path / "sim-final.json").write_text("{not json")
    assert '<span class="bad">sim-final.json: unreadable' in world_rows(tmp_path)[0][1]


def test_a_frame_too_far_from_its_moment_is_not_shown_as_of_it() -> None:
    moments = [Moment(1000.0, 10.0, "turtlebot", "PICK", "Fetch/PICK", "ended")]
    near = Frame("/turtlebot/xtion_rgb_raw", moments[0], 1000.0 + MAX_FRAME_GAP + 3.0, {"format": "x", "data": b""})
    data = BagData(bags=[Path("bag")], topics={"/turtlebot/xtion_rgb_raw": "sensor_msgs/msg/Image"}, frames=[near])
    page = parse(snapshots_section(data, ReportTopics(cameras=("/turtlebot/xtion_rgb_raw",)), moments, ["PICK"]))
    assert page.images == []
    assert page.table("snapshots agent-turtlebot") == [
        ["no framePICK ended at 10.0 sthe nearest frame is +8.0 s from it (more than 5 s)"]
    ]


def test_cameras_belong_to_the_agent_named_in_their_topic() -> None:
    cameras = ["/turtlebot/xtion_rgb_raw/compressed", "/nao/camera/image/compressed"]
    assert agent_cameras("turtlebot", cameras) == ["/turtlebot/xtion_rgb_raw/compressed"]
    assert agent_cameras("nao", cameras) == ["/nao/camera/image/compressed"]
    assert agent_cameras("fetcher", cameras) == cameras  # no camera named after it: every camera
