"""The Monitor tab's live map (issue K.5): the use case's topics found in its configuration, messages
in the runtime codec's wire form drawn at the right scene coordinates, the zoom-map area replayed
by the <ZoomMap> rules, and the whole path over a loopback network into the Monitor tab."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtWidgets import QGraphicsEllipseItem, QGraphicsLineItem, QGraphicsPathItem
from pytestqt.qtbot import QtBot

import ckmconf
from ckmconf.model import System
from editor.views.live import MonitorPanel
from editor.views.sim_feeds import FeedError, feeds_of, plain
from editor.views.sim_map import SCALE, SimMapView, to_scene
from editor.views.sim_state import LiveState
from runtime.network import TopicQoS, open_transport
from runtime.resources import codec
from tests.editor.test_live import cell
from tests.runtime.network.conftest import private_network

LAB = Path(__file__).resolve().parents[2] / "configs" / "usecase" / "lab.xml"


@pytest.fixture(scope="module")
def lab() -> System:
    return ckmconf.load(LAB)


def estimate(x: float, y: float, yaw: float, sx: float = 0.2, sy: float = 0.1, **extra: Any) -> Any:
    """A /nav/pose PoseEstimate as Navigation.AMCL publishes it, through the codec (covariance an array)."""
    covariance = np.diag([sx * sx, sy * sy, 0.01])
    message = {"stamp": 0.0, "pose": {"x": x, "y": y, "yaw": yaw}, "covariance": covariance.ravel(),
               "dispersion": math.hypot(sx, sy), **extra}  # fmt: skip
    return codec.encode(message)


def recognised(*objects: tuple[str, float, float, float]) -> Any:
    """A /recog/objects result of the fusion (map frame; reliability a numpy float32, as the plugins give it)."""
    items = [{"name": n, "shape": "cylinder", "texture": "", "x": x, "y": y, "z": 0.8, "frame": "map",
              "reliability": np.float32(r), "sources": ["rgb", "depth"]} for n, x, y, r in objects]  # fmt: skip
    return codec.encode({"stamp": 0.0, "objects": items, "reliability": np.float32(0.5)})


def close(a: QPointF, b: QPointF) -> bool:
    return abs(a.x() - b.x()) < 1e-6 and abs(a.y() - b.y()) < 1e-6


def test_the_use_case_topics_are_found_in_its_configuration(lab: System) -> None:
    feeds = feeds_of(lab)
    robots = {r.name: r for r in feeds.robots}
    assert set(robots) == {"turtlebot", "nao"}
    assert robots["turtlebot"].truth == "/sim/turtlebot/pose"
    assert robots["turtlebot"].estimates == ("/nav/pose",)
    assert robots["turtlebot"].placed == (1.5, 1.5, 0.785)
    assert robots["nao"].truth is None and robots["nao"].estimates == ()  # it stands where nodes.xml puts it
    assert robots["nao"].placed == (7.6, 6.78, -1.5708)
    assert robots["nao"].head == "/nao/head_state" and robots["turtlebot"].head is None  # not /nao/head_goal
    assert "/recog/objects" in feeds.objects and "/pantilt/target" in feeds.objects
    # the Nao's frames are on the network; the Xtion's only under their node-internal wire name
    assert feeds.cameras == ("/nao/camera/image", "/turtlebot/~xtion_rgb_raw")
    assert feeds.zoom == ("/nav/zoom",) and feeds.particles == ("/nav/particles",)  # Navigation.AMCL's (D215)


def test_robots_objects_and_the_zoom_area_are_drawn_where_the_messages_put_them(qtbot: QtBot, lab: System) -> None:
    feeds = feeds_of(lab)
    assert lab.environment is not None
    state = LiveState(feeds, lab.environment.zoom)
    view = SimMapView()
    qtbot.addWidget(view)
    view.show_environment(lab.environment, feeds.robots)
    nao = view.robots["nao"]
    assert close(nao["truth"].pos(), QPointF(760.0, -678.0)) and nao["truth"].isVisible()
    assert view.bounds.width() == 10 * SCALE and view.bounds.height() == 7 * SCALE  # map 10 × 7 m
    turtlebot = view.robots["turtlebot"]
    assert not turtlebot["truth"].isVisible()  # nothing heard yet

    state.feed("/sim/turtlebot/pose", codec.encode({"x": 1.5, "y": 3.0, "yaw": 0.0}), 99.0)
    state.feed("/sim/turtlebot/pose", codec.encode({"x": 2.0, "y": 3.0, "yaw": 0.5}), 100.0)
    state.feed("/nav/pose", estimate(2.1, 2.9, 0.45), 100.0)
    state.feed("/recog/objects", recognised(("mug", 8.0, 6.1, 0.87), ("can", 7.5, 6.3, 0.4)), 100.0)
    view.show_state(state.snapshot())
    assert close(turtlebot["truth"].pos(), QPointF(200.0, -300.0))
    assert turtlebot["truth"].rotation() == pytest.approx(-math.degrees(0.5))
    assert close(turtlebot["estimate"].pos(), to_scene(2.1, 2.9))
    trail = turtlebot["truth_track"]  # the true trajectory so far: 1.5 → 2 m along y = 3 m
    assert isinstance(trail, QGraphicsPathItem) and trail.isVisible()
    assert trail.path().boundingRect() == QRectF(to_scene(1.5, 3.0), to_scene(2.0, 3.0))
    assert not turtlebot["estimate_track"].isVisible()  # one estimate: no trajectory yet
    ellipse = turtlebot["ellipse"]
    assert isinstance(ellipse, QGraphicsEllipseItem) and ellipse.isVisible()
    # 2σ: σx 0.2 m, σy 0.1 m → half-axes 40 and 20 scene units, the major one along the map's x
    assert ellipse.rect().width() == pytest.approx(80.0) and ellipse.rect().height() == pytest.approx(40.0)
    assert math.cos(math.radians(ellipse.rotation())) == pytest.approx(1.0, abs=1e-9)
    labels = sorted(item.text() for item in view.labels)
    assert labels == ["can cylinder 0.40", "mug cylinder 0.87"]
    mug = next(item for item in view.labels if item.text().startswith("mug"))
    assert (mug.scenePos() - to_scene(8.0, 6.1)).manhattanLength() < 30  # beside its mark
    assert view.zoom.isVisible() and view.zoom_label.text() == "zoom map (replayed)"
    assert close(view.zoom.rect().center(), to_scene(2.1, 2.9))
    assert view.zoom.rect().width() == pytest.approx(400.0)  # 4 × 4 m

    # A newer result replaces the topic's objects. A sighting the fusion could not place yet is its camera's
    # ray (Algorithm 4), drawn 2 m along its map-plane direction; a vertical one has no place on the map.
    rays = [{"name": "box", "x": None, "y": None, "frame": "map", "reliability": 0.3, "origin": [7.6, 6.78, 0.5],
             "direction": [0.0, -0.6, -0.8]},
            {"name": "lamp", "x": None, "y": None, "frame": "map", "reliability": 0.2, "origin": [1, 1, 1],
             "direction": [0, 0, 1]}]  # fmt: skip
    state.feed("/recog/objects", codec.encode({"objects": rays}), 101.0)
    view.show_state(state.snapshot())
    assert [item.text() for item in view.labels] == ["box 0.30 (ray)"]
    lines = [
        i for i in view.scene().items() if isinstance(i, QGraphicsLineItem) and i.pen().style() == Qt.PenStyle.DashLine
    ]
    assert len(lines) == 1
    assert close(lines[0].line().p1(), to_scene(7.6, 6.78)) and close(lines[0].line().p2(), to_scene(7.6, 4.78))

    # The Nao's head turned 0.5 rad to its left: its camera looks that way from where it stands.
    gaze = nao["gaze"]
    assert isinstance(gaze, QGraphicsLineItem) and not gaze.isVisible()
    state.feed("/nao/head_state", codec.encode({"pan": 0.5, "tilt": 0.1}), 102.0)
    view.show_state(state.snapshot())
    looks = (7.6 + 1.5 * math.cos(-1.5708 + 0.5), 6.78 + 1.5 * math.sin(-1.5708 + 0.5))
    assert (
        gaze.isVisible() and close(gaze.line().p1(), to_scene(7.6, 6.78)) and close(gaze.line().p2(), to_scene(*looks))
    )


def test_the_zoom_area_moves_by_the_zoom_map_rules(lab: System) -> None:
    assert lab.environment is not None and lab.environment.zoom is not None  # 4 × 4 m, border 0.1, timeout 10 s
    state = LiveState(feeds_of(lab), lab.environment.zoom)

    def centre_after(x: float, y: float, t: float) -> tuple[float, float]:
        state.feed("/nav/pose", estimate(x, y, 0.0), t)
        zoom = state.snapshot().zoom
        assert zoom is not None and zoom.replayed
        return zoom.x, zoom.y

    assert centre_after(2.0, 2.0, 0.0) == (2.0, 2.0)
    assert centre_after(3.5, 2.0, 1.0) == (2.0, 2.0)  # 0.5 m from the edge: more than the 0.4 m border
    assert centre_after(3.7, 2.0, 2.0) == (3.7, 2.0)  # within the border: re-centred
    assert centre_after(3.8, 2.0, 12.5) == (3.8, 2.0)  # the timeout


def test_particles_are_drawn_when_an_estimate_carries_them(qtbot: QtBot, lab: System) -> None:
    feeds = feeds_of(lab)
    state = LiveState(feeds)
    view = SimMapView()
    qtbot.addWidget(view)
    view.show_environment(lab.environment, feeds.robots)
    cloud = np.array([[1.0, 1.0, 0.0], [1.5, 2.0, 0.1], [2.0, 1.5, 0.2]])
    state.feed("/nav/pose", estimate(1.5, 1.5, 0.0, particles=cloud), 5.0)
    view.show_state(state.snapshot())
    assert view.particles.isVisible()
    box = view.particles.path().boundingRect()
    assert box.center().x() == pytest.approx(150.0) and box.center().y() == pytest.approx(-150.0)
    assert box.width() == pytest.approx(100.0 + 3.0)  # 1 m of particles plus one 3 cm dot
    assert view.zoom.isVisible() is False  # no <ZoomMap> given to this state: nothing replayed


def test_results_leave_the_map_after_their_topics_lifespan(qtbot: QtBot, lab: System) -> None:
    now = [0.0]
    state = LiveState(feeds_of(lab), clock=lambda: now[0])
    view = SimMapView()
    qtbot.addWidget(view)
    view.show_environment(lab.environment, feeds_of(lab).robots)
    state.feed("/recog/objects", recognised(("mug", 8.0, 6.1, 0.87)), 1.0)  # lifespan 2.4 s (nodes.xml)
    target = {"stamp": 1.0, "label": "mug", "frame": "map", "x": 8.0, "y": 6.2, "z": 0.8, "reliability": 0.8}
    state.feed("/pantilt/target", codec.encode(target), 1.0)  # the Nao's target, lifespan 5 s
    now[0] = 2.0
    view.show_state(state.snapshot())
    assert sorted(item.text() for item in view.labels) == ["mug 0.80 (/pantilt/target)", "mug cylinder 0.87"]
    now[0] = 3.0  # the fusion has said nothing for 3 s: its objects are gone, the target stays
    view.show_state(state.snapshot())
    assert [item.text() for item in view.labels] == ["mug 0.80 (/pantilt/target)"]
    now[0] = 6.0
    view.show_state(state.snapshot())
    assert view.labels == []


def test_unreadable_messages_are_reported_not_drawn(lab: System) -> None:
    state = LiveState(feeds_of(lab))
    state.feed("/sim/turtlebot/pose", {"~nd": ["|O", [1], b"x"]}, 1.0)
    assert state.snapshot().truth == {}
    assert "dtype '|O'" in state.snapshot().errors["/sim/turtlebot/pose"]
    with pytest.raises(FeedError, match="does not fit"):
        plain({"~nd": ["<f8", [3], b"\0" * 16]})
    with pytest.raises(KeyError, match="not a topic of the live views"):
        state.feed("/nowhere", {}, 1.0)


def test_the_monitor_tab_draws_what_arrives_on_the_network(qtbot: QtBot, lab: System) -> None:
    network = private_network()
    editor_side = open_transport(network, name="editor")
    sim_side = open_transport(network, name="sim")
    for transport in (editor_side, sim_side):
        transport.setup()
        transport.start()
    panel = MonitorPanel(lambda: editor_side)
    qtbot.addWidget(panel)
    try:
        panel.start(lab)
        feeds = feeds_of(lab)
        frame = {"stamp": 1.0, "width": 2, "height": 1, "encoding": "rgb8", "data": bytes([255, 0, 0, 0, 0, 255])}
        sent: dict[str, Any] = {
            "/sim/turtlebot/pose": codec.encode({"x": 4.0, "y": 2.5, "yaw": 1.0}),
            "/nav/pose": estimate(4.2, 2.4, 0.9),
            "/recog/objects": recognised(("mug", 8.0, 6.1, 0.87)),
            "/nao/camera/image": frame,
            "/nav/particles": codec.encode({"stamp": 1.0, "frame": "map", "total": 500, "x": np.array([4.0, 4.4]),
                                            "y": np.array([2.3, 2.5]), "yaw": np.zeros(2),
                                            "weight": np.full(2, 0.002)}),
            "/nav/zoom": codec.encode({"stamp": 1.0, "frame": "map", "mode": "2.5D", "x": 4.2, "y": 2.4, "width": 4.0,
                                       "depth": 4.0, "height": 2.0, "reason": "border", "since": 0.5,
                                       "objects": ["desk", "chair"], "avoided": []}),
        }
        publishers = {t: sim_side.publisher(TopicQoS(t, feeds.types[t])) for t in sent}
        for topic in sent:
            assert sim_side.wait_for_subscribers(topic, 1, timeout=20.0), topic
        turtlebot = panel.live.map.robots["turtlebot"]

        def drawn() -> bool:
            for topic, value in sent.items():  # best-effort streams: keep sending, as the simulation does
                publishers[topic].publish(value)
            panel.refresh()
            zoom = panel.live.map.zoom_label.text() == "zoom map (border, 2 objects)"  # the published, not replayed
            return (turtlebot["truth"].isVisible() and turtlebot["estimate"].isVisible() and bool(panel.live.map.labels)
                    and "/nao/camera/image" in panel.live.cameras.images and panel.live.map.particles.isVisible()
                    and zoom)  # fmt: skip

        deadline = time.monotonic() + 20.0
        while not drawn() and time.monotonic() < deadline:
            qtbot.wait(100)
        assert drawn(), "the live map did not show the published state within 20 s"
        assert close(turtlebot["truth"].pos(), to_scene(4.0, 2.5))
        assert close(turtlebot["estimate"].pos(), to_scene(4.2, 2.4))
        assert [item.text() for item in panel.live.map.labels] == ["mug cylinder 0.87"]
        image = panel.live.cameras.images["/nao/camera/image"]
        assert (image.width(), image.height()) == (2, 1)
        assert image.pixel(0, 0) & 0xFFFFFF == 0xFF0000 and image.pixel(1, 0) & 0xFFFFFF == 0x0000FF  # red, blue
        table = panel.topics_table  # the nodes' topics are counted too, not only the system's own
        counted = {cell(table, r, 0) for r in range(table.rowCount())}
        assert {"/sim/turtlebot/pose", "/nav/pose", "/recog/objects"} <= counted
        assert panel.live.map.particles.path().boundingRect().center() == to_scene(4.2, 2.4)
        assert close(panel.live.map.zoom.rect().center(), to_scene(4.2, 2.4))
        assert "Particles" not in panel.live.notes.text() and "Zoom map" not in panel.live.notes.text()
    finally:
        panel.timer.stop()
        panel.live.stop()
        sim_side.stop()
        editor_side.stop()


def test_ros_typed_topics_are_found_as_the_configuration_s_own_types_are() -> None:
    """A system on ROS types (sensor_msgs/msg/Image, no MessageType of its own) gets its cameras shown."""
    system = ckmconf.load(LAB.parents[1] / "examples" / "sim_ros_types.xml")
    feeds = feeds_of(system)
    assert feeds.cameras == ("/camera/depth/image_raw", "/camera/rgb/image_raw")
    assert [r.name for r in feeds.robots] == ["turtlebot"]


def test_a_marking_is_drawn_pale_and_dashed(qtbot: QtBot, tmp_path: Path) -> None:
    """D294: a ``<Geometry2D height="0">`` is drawn as a marking, an object of no height as before."""
    path = tmp_path / "room.xml"
    path.write_text(
        '<Part xmlns="urn:ckm:1" version="1.0"><Environment name="e"><Map xmin="0" ymin="0" xmax="4" ymax="2"/>'
        '<Semantic tag="thing"/>'
        '<Object name="pad" tag="thing"><Pose x="1" y="1"/><Geometry2D height="0"><Circle radius="0.3"/></Geometry2D>'
        '</Object><Object name="desk" tag="thing"><Pose x="3" y="1"/><Geometry2D><Circle radius="0.3"/></Geometry2D>'
        "</Object></Environment></Part>"
    )
    view = SimMapView()
    qtbot.addWidget(view)
    view.show_environment(ckmconf.load(path).environment, ())
    drawn = {i.toolTip(): i for i in view.scene().items() if isinstance(i, QGraphicsPathItem) and i.toolTip()}
    pad, desk = drawn["pad (thing, a marking)"], drawn["desk (thing)"]
    assert pad.pen().style() == Qt.PenStyle.DashLine and pad.brush().color().alphaF() < 0.5
    assert desk.pen().style() == Qt.PenStyle.SolidLine and desk.brush().color().alphaF() == 1.0
