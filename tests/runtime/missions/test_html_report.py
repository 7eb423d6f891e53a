"""ckm-mission report RUN_DIR --html: a run recorded with RunRecorder, a real rosbag2 bag written
with BagRecorder (poses, detections, images as ``ckm-run --record`` writes them), the page parsed."""

from __future__ import annotations

import base64
import io
import json
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.image import imread

from runtime.missions import cli
from runtime.missions.html_report import Options, build_html, main
from runtime.missions.recording import RunRecorder, read_run
from runtime.missions.report import build_report
from runtime.missions.report_bag import Moment, ReportTopics, find_bags, read_bags
from runtime.ros.bag import BagRecorder, Storage
from runtime.ros.types import RosTypes

REPO = Path(__file__).resolve().parents[3]
LAB = REPO / "configs" / "usecase" / "lab.xml"
WALL = 1_800_000_000.0  # the run's wall-clock start (epoch s)

# The ckm_msgs types runtime.ros.config generates for the use case's MessageTypes (network.xml).
CKM_MSGS = {
    "ckm_msgs/msg/Pose2D": "float64 x\nfloat64 y\nfloat64 yaw\n",
    "ckm_msgs/msg/PoseEstimate": "builtin_interfaces/Time stamp\nckm_msgs/Pose2D pose\nfloat64[9] covariance\n"
    "float64 dispersion\n",
    "ckm_msgs/msg/DetectedObject": "string label\nstring shape\nstring texture\nfloat64 x\nfloat64 y\nfloat64 z\n"
    "float32 reliability\n",
    "ckm_msgs/msg/Detections": "builtin_interfaces/Time stamp\nstring source\nckm_msgs/DetectedObject[] objects\n"
    "float32 reliability\n",
    "ckm_msgs/msg/Image": "builtin_interfaces/Time stamp\nuint32 width\nuint32 height\nstring encoding\nuint8[] data\n",
    "ckm_msgs/msg/ZoomArea": "float64 x\nfloat64 y\nfloat64 width\nfloat64 depth\n",
}
TOPICS = {
    "/nav/pose": "ckm_msgs/msg/PoseEstimate",
    "/sim/turtlebot/pose": "geometry_msgs/msg/PoseStamped",
    "/recog/objects": "ckm_msgs/msg/Detections",
    "/nav/zoom": "ckm_msgs/msg/ZoomArea",
    "/turtlebot/xtion_rgb_raw": "ckm_msgs/msg/Image",
    "/nao/camera/image": "sensor_msgs/msg/Image",
}
LAB_TOPICS = ReportTopics(
    estimate="/nav/pose",
    truth=("/sim/turtlebot/pose",),
    fused="/recog/objects",
    cameras=("/turtlebot/xtion_rgb_raw", "/nao/camera/image"),
    zoom=("/nav/zoom",),
)
"""The topics of TOPICS as the command line names them, for a run reported without its configuration."""
TURTLEBOT = [  # (enter, exit, path, nested mission or None, performance)
    (0.0, 2.0, "INIT", None, 1.0),
    (2.0, 40.0, "Navigation", "NavigationCoop", None),
    (2.0, 10.0, "Navigation/NAV", None, 0.9),
    (10.0, 40.0, "Navigation/WAIT", None, 0.8),
    (40.0, 100.0, "ObjectInteraction", "ObjectInteractionCoop", None),
    (40.0, 50.0, "ObjectInteraction/SPOT", None, 0.7),
    (50.0, 80.0, "ObjectInteraction/APPR", None, 0.95),
    (80.0, 100.0, "ObjectInteraction/PICK", None, 0.9),
    (100.0, 150.0, "ObjectPlace", "ObjectPlace", None),
    (100.0, 130.0, "ObjectPlace/NAV", None, 0.85),
    (130.0, 135.0, "ObjectPlace/WAIT", None, 0.8),
    (135.0, 145.0, "ObjectPlace/PLACE", None, 1.0),
    (145.0, 150.0, "ObjectPlace/BACK", None, 0.9),
    (150.0, 151.0, "END", None, 1.0),
]


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def record_agent(
    run_dir: Path, agent: str, mission: str, states: list[Any], outcome: str, lost: float | None = None
) -> None:
    clock = Clock()
    with RunRecorder(run_dir, agent, clock=clock, wall_clock=lambda: WALL) as rec:
        rec.write("start", mission=mission, plan="cooperative", wall=WALL)
        events = []
        for begin, end, path, nested, performance in states:
            full = f"{mission}/{path}"
            state = path.rsplit("/", 1)[-1]
            events.append((begin, 0, "enter", {"path": full, "state": state, "mission": mission, "nested": nested}))
            if performance is not None:
                for k, t in enumerate(np.linspace(begin, end, 3)[:-1]):
                    events.append((t, 1, "progress", {"path": full, "progress": k / 2, "performance": performance}))
            events.append((end, -1 - full.count("/"), "exit", {"path": full, "state": state, "reason": "transition"}))
        if lost is not None:
            events.append((lost, 2, "agent-lost", {"lost": "nao"}))
        for t, _, kind, fields in sorted(events, key=lambda e: (e[0], e[1])):
            clock.now = float(t)
            rec.write(kind, **fields)
        clock.now = states[-1][1]
        rec.write("end", outcome=outcome)


def ros_types() -> RosTypes:
    types = RosTypes()
    for name, text in CKM_MSGS.items():
        types.add_msg(name, text)
    return types


def robot_xy(t: float) -> tuple[float, float]:
    """The robot drives from (1.5, 1.5) to (7.6, 5.4) by t = 80 s, then back."""
    s = min(t, 80.0) / 80.0 if t <= 100 else max(0.0, 1 - (t - 100) / 50)
    return 1.5 + 6.1 * s, 1.5 + 3.9 * s


def write_bag(
    run_dir: Path, topics: dict[str, str] = TOPICS, storage: Storage = "mcap", empty: dict[str, str] | None = None
) -> Path:
    """A bag of ``topics`` over the run, and the ``empty`` topics declared without a message."""
    path = run_dir / "bag"
    with BagRecorder(path, storage=storage, types=ros_types()) as bag:
        for topic, type_name in {**topics, **(empty or {})}.items():
            bag.add_topic(topic, type_name)
        for t in np.arange(0.0, 151.0, 1.0):
            x, y = robot_xy(t)
            stamp = WALL + t
            if "/nav/pose" in topics:
                pose = {"stamp": stamp, "pose": {"x": x + 0.05, "y": y, "yaw": 0.5}, "dispersion": 0.1}
                bag.write("/nav/pose", pose, stamp)
            if "/sim/turtlebot/pose" in topics:
                truth = {"header": {"stamp": stamp, "frame_id": "map"}, "pose": {"position": {"x": x, "y": y}}}
                bag.write("/sim/turtlebot/pose", truth, stamp)
            if "/recog/objects" in topics and 40 <= t <= 100:
                distance = float(np.hypot(7.6 - x, 6.1 - y))
                target = {"label": "cylinder_red_stripes", "shape": "cylinder", "texture": "red_stripes", "x": 7.6}
                target |= {"y": 6.1, "z": 0.36, "reliability": max(0.3, 1.0 - 0.1 * distance)}
                other = {"label": "box_orange", "shape": "box", "texture": "orange_plain", "x": 7.4, "y": 6.3}
                other |= {"reliability": 0.5}
                bag.write("/recog/objects", {"stamp": stamp, "objects": [target, other], "reliability": 0.8}, stamp)
            if "/nav/zoom" in topics and t % 20 == 0:
                bag.write("/nav/zoom", {"x": x, "y": y, "width": 4.0, "depth": 4.0}, stamp)
            level = int(t) % 256
            if "/turtlebot/xtion_rgb_raw" in topics:
                pixels = np.full((6, 8, 3), level, dtype=np.uint8)
                image = {"stamp": stamp, "width": 8, "height": 6, "encoding": "rgb8", "data": pixels.tobytes()}
                bag.write("/turtlebot/xtion_rgb_raw", image, stamp + 0.3)
            if "/nao/camera/image" in topics:
                bag.write("/nao/camera/image", np.full((4, 5), level, dtype=np.uint8), stamp + 0.3)
    return path


def make_run(run_dir: Path, *, bag: bool = True, config: bool = True) -> Path:
    record_agent(run_dir, "turtlebot", "Agent1FetchCoop", TURTLEBOT, "succeeded", lost=60.0)
    nao = [(0.0, 20.0, "OBJ_TRACK", None, 1.0), (20.0, 45.0, "OBJ_FIX", None, 0.6)]
    record_agent(run_dir, "nao", "Agent2Spot", nao, "spotted")
    if config:
        (run_dir / "stats.json").write_text(json.dumps({"config": str(LAB), "system": "usecase-lab", "nodes": {}}))
    log = "2026-11-23 11:18:52,425 ERROR ckm.node: remote_pc: task nav failed 3 times\n"
    log += "2026-11-23 11:18:53,425 ERROR ckm.node: remote_pc: task nav failed 4 times\n"
    log += "2026-11-23 11:18:54,000 WARNING ckm.node: cell: safe-stop {'actuator': 'x'}\n"
    (run_dir / "ckm.log").write_text(log)
    alarm = {"node": "remote_pc", "kind": "alarm", "alarm": "pose_stale", "severity": "warning", "time": WALL}
    cleared = dict(alarm, kind="alarm-cleared")
    (run_dir / "events.jsonl").write_text("\n".join(json.dumps(e) for e in (alarm, cleared, alarm)) + "\n")
    if bag:
        write_bag(run_dir)
    return run_dir


class Page(HTMLParser):
    """Tables (by class), images, paragraphs with a class, and every attribute value of the page."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: list[tuple[str, list[list[str]]]] = []
        self.images: list[tuple[str, str]] = []
        self.notes: list[str] = []
        self.attributes: list[str] = []
        self.tags: set[str] = set()
        self._cell: list[str] | None = None
        self._note: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        values = dict(attrs)
        self.tags.add(tag)
        self.attributes += [v or "" for v in values.values()]
        if tag == "table":
            self.tables.append((values.get("class") or "", []))
        elif tag == "tr":
            self.tables[-1][1].append([])
        elif tag in ("td", "th"):
            self._cell = []
        elif tag == "img":
            self.images.append((values.get("alt") or "", values.get("src") or ""))
        elif tag == "p" and values.get("class"):
            self._note = []

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._cell is not None:
            self.tables[-1][1][-1].append("".join(self._cell))
            self._cell = None
        elif tag == "p" and self._note is not None:
            self.notes.append("".join(self._note))
            self._note = None

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell.append(data)
        if self._note is not None:
            self._note.append(data)

    def table(self, css: str) -> list[list[str]]:
        return next(rows for name, rows in self.tables if set(css.split()) <= set(name.split()))


def parse(text: str) -> Page:
    page = Page()
    page.feed(text)
    page.close()
    return page


def decode(src: str) -> np.ndarray:
    prefix = "data:image/png;base64,"
    assert src.startswith(prefix)
    return np.asarray(imread(io.BytesIO(base64.b64decode(src[len(prefix) :])), format="png"))


def test_the_page_holds_table_7_9_figures_snapshots_and_problems(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = make_run(tmp_path / "run")
    out = tmp_path / "out" / "page.html"
    assert main(run_dir, out=out) == 0
    assert f"report: {out}" in capsys.readouterr().out
    page = parse(out.read_text(encoding="utf-8"))
    # self-contained: no script, stylesheet link or external address; every picture an embedded PNG
    assert not page.tags & {"script", "link", "iframe"}
    assert not [v for v in page.attributes if v.startswith(("http", "//", "file:"))]
    assert page.images and all(decode(src).size for _, src in page.images)
    alts = [alt for alt, _ in page.images]
    assert {"Fig. 7.23 plan", "Fig. 7.16", "Fig. 7.19"} <= set(alts)
    # Table 7.9 per agent agrees with build_report
    report = build_report(read_run(run_dir), "leaf")
    for agent in report.agents:
        rows = page.table(f"agent-{agent.agent}")
        assert rows[0] == ["State", "Execution Time (s)", "Contribution to mission (%)", "Avg. Performance"]
        expected = [
            [r.label, "+".join(f"{v:.3f}" for v in r.visits), "+".join(f"{100 * c:.1f}" for c in r.contribution),
             "-" if r.performance is None else f"{r.performance:.2f}"]
            for r in agent.rows
        ]  # fmt: skip
        assert rows[1:] == expected
    assert ["ObjectInteraction/APPR", "30.000", "19.9", "0.95"] in page.table("agent-turtlebot")
    # the thesis' values (the lab package's reference table) next to ours where the states match
    thesis = {row[0]: row for row in page.table("reference agent-turtlebot")[1:]}
    assert thesis["NAVIGATION"][2:4] == ["56.676+52.856", "38.000+35.000"]
    assert (
        thesis["APPR-PICK"][3] == "50.000"
        and thesis["APPR-PICK"][1] == "ObjectInteraction/APPR, ObjectInteraction/PICK"
    )
    nao = {row[0]: row for row in page.table("reference agent-nao")[1:]}
    assert nao["SPOT_FIX"][2:4] == ["75.327", "25.000"]
    # header: outcomes judged against the missions' success finals (configuration from stats.json)
    agents = {row[0]: row for row in page.table("agents")[1:]}
    assert agents["turtlebot"][2] == "success (succeeded)" and agents["nao"][2] == "success (spotted)"
    summary = {row[0]: row[1] for row in page.table("summary")}
    assert summary["System"] == "usecase-lab" and summary["Plan"] == "cooperative"
    assert summary["Mission time"] == "151.0 s" and summary["Run date"].startswith("2027-01-15")
    assert summary["Off-line validation"].startswith("not in the run directory")
    assert summary["Problems"] == "5 in 3 kind(s)"
    # camera frames: per agent, its own camera's frame nearest each entry and end of the states on
    # its mission's success route (Fig. 7.22, 7.24; the cameras and states are the configuration's)
    frames = {alt: decode(src) for alt, src in page.images if " at " in alt and alt.split()[0] in ("turtlebot", "nao")}
    assert len(frames) == 26  # turtlebot: 11 visits entered and ended (no DOCK in this run); nao: 2
    spot = frames["turtlebot Agent1FetchCoop/ObjectInteraction/SPOT entered at 40.0 s"]
    assert round(float(spot.reshape(-1)[0]) * 255) == 40  # the frame of t = 40 (stamped 40.3 s)
    fixed = frames["nao Agent2Spot/OBJ_FIX ended at 45.0 s"]
    assert fixed.shape[:2] == (4, 5) and abs(float(fixed.reshape(-1)[0]) * 255 - 45) <= 1  # the Nao's own camera
    turtlebot = [cell for row in page.table("snapshots agent-turtlebot") for cell in row]
    assert turtlebot[:4] == [
        "INIT entered at 0.0 sframe +0.30 s from it",
        "INIT ended at 2.0 sframe +0.30 s from it",
        "NAV entered at 2.0 sframe +0.30 s from it",
        "NAV ended at 10.0 sframe +0.30 s from it",
    ]
    assert [c.split(" at ")[0] for c in turtlebot[4:]] == [
        f"{state} {edge}"
        for state in ("WAIT", "SPOT", "APPR", "PICK", "NAV", "WAIT", "PLACE", "BACK", "END")
        for edge in ("entered", "ended")
    ]
    assert turtlebot[-1] == "END ended at 151.0 sframe -0.70 s from it"  # the last frame, of t = 150
    assert [cell for row in page.table("snapshots agent-nao") for cell in row] == [
        "OBJ_TRACK entered at 0.0 sframe +0.30 s from it",
        "OBJ_TRACK ended at 20.0 sframe +0.30 s from it",
        "OBJ_FIX entered at 20.0 sframe +0.30 s from it",
        "OBJ_FIX ended at 45.0 sframe +0.30 s from it",
    ]
    assert summary["World at the end"] == "no simulated world (no sim-final.json)"
    text = out.read_text(encoding="utf-8")
    assert "target &#x27;cylinder_red_stripes cylinder red_stripes&#x27;: the object recognised most reliably" in text
    # problems, counted
    problems = {row[2]: row for row in page.table("problems")[1:]}
    assert problems["ckm.node: remote_pc: task nav failed # times"][3] == "2"
    assert problems["remote_pc: alarm (alarm pose_stale)"][3] == "2"
    assert problems["turtlebot: agent nao lost"][3] == "1"
    assert not any("alarm-cleared" in what for what in problems)
    assert not [n for n in page.notes if n.startswith("No ")]  # nothing is missing from this run


def test_a_run_without_bag_or_configuration_says_what_is_missing(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run", bag=False, config=False)
    text, errors = build_html(run_dir)
    assert errors == []
    page = parse(text)
    notes = " | ".join(page.notes)
    assert "No bag in the run directory" in notes
    assert "no configuration (no stats.json naming it, no --config)" in notes
    no_pose = "No estimated trajectory: no topic to read it from (none known from the configuration; name one with "
    assert no_pose + "--pose-topic)." in notes
    assert "No recognition results" in notes and "No camera frames" in notes
    assert {"Fig. 7.23 plan"} <= {alt for alt, _ in page.images}  # the recordings still give Table 7.9 and Fig. 7.23
    assert "Fig. 7.16" not in {alt for alt, _ in page.images}
    agents = {row[0]: row for row in page.table("agents")[1:]}
    assert agents["turtlebot"][2] == "succeeded (mission not in the configuration: success unknown)"


def test_topics_absent_from_the_bag_are_noted_and_others_drawn(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run", bag=False, config=False)
    write_bag(run_dir, {"/nav/pose": TOPICS["/nav/pose"]}, empty={"/nav/zoom": TOPICS["/nav/zoom"]})
    (run_dir / "validation.json").write_text('{"ok": true, "missions": [{"mission": "Agent1FetchCoop", "ok": true}]}')
    page = parse(build_html(run_dir, Options(topics=LAB_TOPICS))[0])
    notes = " | ".join(page.notes)
    assert "No true trajectory: topic /sim/turtlebot/pose not in the bag." in notes
    assert "No zoom-map areas recorded: in the bag /nav/zoom 0 message(s), none usable" in notes
    assert "replayed" not in notes  # no configuration, no <ZoomMap>
    assert "No recognition results" in notes and "No camera frames" in notes
    assert "Fig. 7.16" in {alt for alt, _ in page.images}
    assert dict(page.table("summary"))["Off-line validation"] == "passed (Agent1FetchCoop coherent)"
    assert ["/nav/pose", "ckm_msgs/msg/PoseEstimate", "151"] in page.table("topics")


def test_a_corrupt_bag_is_named_and_the_report_still_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = make_run(tmp_path / "run", bag=False, config=False)
    bag = write_bag(run_dir, {"/nav/pose": TOPICS["/nav/pose"]})
    storage = next(bag.glob("*.mcap"))
    data = storage.read_bytes()
    storage.write_bytes(data[:40] + b"\xff" * 200 + data[240:])
    out = tmp_path / "report.html"
    assert cli.main(["report", str(run_dir), "--html", "--pose-topic", "/nav/pose", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert str(storage) in err and "rosbag2 bag" in err
    page = parse(out.read_text(encoding="utf-8"))
    assert any(str(storage) in n for n in page.notes)


def test_cli_options_choose_topics_target_and_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run_dir = make_run(tmp_path / "run", bag=False, config=False)
    (tmp_path / "elsewhere").mkdir()
    bag = write_bag(tmp_path / "elsewhere")
    args = ["report", str(run_dir), "--html", "--bag", str(bag), "--target", "box orange", "--truth-topic", "/none"]
    args += ["--config", str(LAB)]  # the topics not named are the configuration's
    assert cli.main([*args, "--camera-topic", "/nao/camera/image", "--out", str(tmp_path / "r.html")]) == 0
    page = parse((tmp_path / "r.html").read_text(encoding="utf-8"))
    assert "No true trajectory: topic /none not in the bag." in page.notes
    # one camera now, the Nao's: shown for the turtlebot too, no camera being named after it
    assert len([alt for alt, _ in page.images if alt.startswith(("turtlebot Agent1", "nao Agent2"))]) == 26
    assert page.table("snapshots agent-turtlebot") and page.table("snapshots agent-nao")
    assert capsys.readouterr().err == ""
    text = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert "target &#x27;box orange&#x27; (--target)" in text


def test_the_configuration_named_by_a_node_process_statistics_gives_the_map(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run", bag=False, config=False)
    write_bag(run_dir, {"/nav/pose": TOPICS["/nav/pose"]})
    environment = (REPO / "configs" / "usecase" / "environment.xml").read_text(encoding="utf-8")
    (tmp_path / "environment.xml").write_text(environment, encoding="utf-8")  # it includes nothing
    system = '<System xmlns="urn:ckm:1" version="1.0" name="tiny"><Include href="environment.xml"/></System>'
    (tmp_path / "tiny.xml").write_text(system)
    (run_dir / "stats-remote_pc.json").write_text(json.dumps({"config": "tiny.xml", "system": "tiny"}))
    # tiny.xml is found next to the run directory; it has no service, so the pose topic is named
    page = parse(build_html(run_dir, Options(topics=ReportTopics(estimate="/nav/pose")))[0])
    summary = dict(page.table("summary"))
    assert summary["System"] == "tiny" and summary["Configuration"] == str(run_dir.parent / "tiny.xml")
    assert "Fig. 7.16" in {alt for alt, _ in page.images}
    assert not [n for n in page.notes if "<Environment>" in n]
    replayed = "The zoom-map areas drawn are replayed from the estimated trajectory with the configuration's "
    replayed += "<ZoomMap> (4 × 4 m, re-centred within 10% of its border or after 10 s, §6.1.3)."
    assert replayed in page.notes


def test_a_configuration_that_does_not_load_or_is_gone_is_noted(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run", bag=False, config=False)
    (tmp_path / "broken.xml").write_text("<System")
    (run_dir / "stats.json").write_text(json.dumps({"config": str(tmp_path / "broken.xml"), "system": "lab"}))
    notes = " | ".join(parse(build_html(run_dir)[0]).notes)
    assert f"configuration {tmp_path / 'broken.xml'} does not load: " in notes
    (run_dir / "stats.json").write_text(json.dumps({"config": "gone.xml", "system": "lab"}))
    assert "configuration gone.xml (stats.json) not found; give it with --config" in parse(build_html(run_dir)[0]).notes


def test_the_bags_of_several_processes_are_merged_in_time_order(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run", bag=False, config=False)
    write_bag(run_dir, {"/nav/pose": TOPICS["/nav/pose"]}).rename(run_dir / "bag-remote_pc")
    write_bag(run_dir, {"/nao/camera/image": TOPICS["/nao/camera/image"], "/recog/objects": TOPICS["/recog/objects"]})
    moment = Moment(WALL + 20.0, 20.0, "nao", "OBJ_FIX", "Agent2Spot/OBJ_FIX", "entered")
    data = read_bags(find_bags(run_dir), LAB_TOPICS, [moment])
    assert data.bags == [run_dir / "bag", run_dir / "bag-remote_pc"] and data.errors == []
    assert [t for t, _, _ in data.poses["/nav/pose"]] == sorted(t for t, _, _ in data.poses["/nav/pose"])
    assert [f.topic for f in data.frames] == ["/nao/camera/image"]
    assert [f.time - WALL for f in data.frames] == pytest.approx([20.3])
    page = parse(build_html(run_dir, Options(topics=LAB_TOPICS))[0])
    assert {"Fig. 7.16", "Fig. 7.19"} <= {alt for alt, _ in page.images}
    assert not [n for n in page.notes if n.startswith("No distance")]  # poses of one bag, objects of the other


def test_html_refuses_json_and_depth_and_a_missing_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as refused:
        cli.main(["report", str(tmp_path), "--html", "--json"])
    assert refused.value.code == 2 and "--html goes without --json and --depth" in capsys.readouterr().err
    assert cli.main(["report", str(tmp_path / "none"), "--html"]) == 1
    assert "none: no such run directory" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()


def test_options_name_no_topic_and_no_state_of_their_own() -> None:
    options = Options()  # the configuration's own are taken (runtime.missions.report_topics)
    assert options.topics == ReportTopics("", (), "", (), (), ()) and options.topics.wanted() == set()
    assert options.snapshot_states is None


def test_a_sqlite3_bag_is_read_like_an_mcap_one(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run", bag=False, config=False)
    write_bag(run_dir, {"/nav/pose": TOPICS["/nav/pose"], "/recog/objects": TOPICS["/recog/objects"]}, "sqlite3")
    page = parse(build_html(run_dir, Options(topics=LAB_TOPICS))[0])
    assert {"Fig. 7.16", "Fig. 7.19"} <= {alt for alt, _ in page.images}
    assert ["/recog/objects", "ckm_msgs/msg/Detections", "61"] in page.table("topics")
