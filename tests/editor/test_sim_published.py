"""The live map draws the particle cloud and the zoom-map area Navigation.AMCL publishes (issue K.5,
D215): the real plugin's messages (its filter run on scans ray-cast in the lab), through the codec,
into the Monitor tab's state and map; a malformed cloud or area is refused with its reason, not drawn."""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np
import pytest
from PySide6.QtCore import QRectF
from pytestqt.qtbot import QtBot

from ckmconf.model import System
from editor.views.sim_feeds import feeds_of
from editor.views.sim_map import SCALE, SimMapView, to_scene
from editor.views.sim_state import LiveState
from runtime.resources import codec
from tests.editor.test_sim_map import estimate
from tests.plugins.navigation.test_live import HOME, lab, lab_navigation, step


@pytest.fixture(scope="module")
def system() -> System:
    return lab()


def view_of(qtbot: QtBot, system: System) -> SimMapView:
    view = SimMapView()
    qtbot.addWidget(view)
    feeds = feeds_of(system)
    view.show_environment(system.environment, feeds.robots)
    return view


def test_the_navigations_own_cloud_and_zoom_area_are_drawn_not_replayed(qtbot: QtBot, system: System) -> None:
    assert system.environment is not None
    state = LiveState(feeds_of(system), system.environment.zoom)
    view = view_of(qtbot, system)
    nav = lab_navigation()
    first = step(nav, HOME, 0, 0.0)
    state.feed("/nav/pose", codec.encode(first["pose"]), 0.0)
    replayed = state.snapshot().zoom
    assert replayed is not None and replayed.replayed  # nothing on /nav/zoom yet: the <ZoomMap> rules
    for k in range(1, 3):
        result = step(nav, HOME, k, 0.8 * k)
    for output, topic in (("pose", "/nav/pose"), ("particles", "/nav/particles"), ("zoom", "/nav/zoom")):
        state.feed(topic, codec.encode(result[output]), 1.6)
    now = state.snapshot()
    view.show_state(now)
    assert now.errors == {}
    cloud, area = result["particles"], result["zoom"]
    assert now.particles is not None and now.particles.shape == (200, 2)
    assert view.particles.isVisible()
    dot = 0.03 * SCALE  # the map draws each particle as a 3 cm square
    expected = QRectF(to_scene(cloud["x"].min(), cloud["y"].max()), to_scene(cloud["x"].max(), cloud["y"].min()))
    box = view.particles.path().boundingRect()
    for got, want in ((box.left(), expected.left() - dot / 2), (box.right(), expected.right() + dot / 2),
                      (box.top(), expected.top() - dot / 2), (box.bottom(), expected.bottom() + dot / 2)):  # fmt: skip
        assert got == pytest.approx(want, abs=1e-6)
    zoom = view.zoom.rect()
    assert (zoom.center().x(), zoom.center().y()) == pytest.approx((area["x"] * SCALE, -area["y"] * SCALE))
    assert zoom.width() == pytest.approx(4 * SCALE) and zoom.height() == pytest.approx(4 * SCALE)
    count = len(area["objects"])
    assert count >= 1 and view.zoom_label.text() == f"zoom map (start, {count} object{'' if count == 1 else 's'})"
    # the published area stays until the Navigation moves it: estimates far off replay nothing any more
    state.feed("/nav/pose", estimate(6.0, 5.0, 0.0), 2.4)
    view.show_state(state.snapshot())
    assert view.zoom.rect() == zoom and not view.zoom_label.text().endswith("(replayed)")


GOOD_CLOUD = {"stamp": 1.0, "frame": "map", "total": 3, "x": np.array([1.0, 1.5, 2.0]), "y": np.array([1.0, 2.0, 1.5]),
              "yaw": np.zeros(3), "weight": np.full(3, 1 / 3)}  # fmt: skip


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"x": np.array([1.0, math.nan, 2.0])}, r"holds 1 of 3 positions that are not finite \(NaN or inf\)"),
        ({"y": np.array([1.0, np.inf, 1.5])}, r"holds 1 of 3 positions that are not finite"),
        ({"y": np.array([1.0, 2.0])}, r"x and y must be two arrays of one length, got shapes \(3,\) and \(2,\)"),
        ({"x": np.ones((3, 2)), "y": np.ones((3, 2))}, r"got shapes \(3, 2\) and \(3, 2\)"),
        ({"x": "1 2 3"}, "a particle cloud's x must be numbers, got str"),
        ({"frame": "odom"}, "a particle cloud in frame 'odom', not the map's"),
        ({"x": None, "y": None, "particles": np.ones((4, 1))}, r"N rows of x, y\[, yaw, weight\], .* \(4, 1\)"),
    ],
)
def test_a_malformed_cloud_is_refused_with_its_reason_and_not_drawn(
    qtbot: QtBot, system: System, change: dict[str, Any], message: str
) -> None:
    state = LiveState(feeds_of(system))
    view = view_of(qtbot, system)
    bad = {k: v for k, v in {**GOOD_CLOUD, **change}.items() if v is not None}
    state.feed("/nav/particles", codec.encode(bad), 1.0)
    now = state.snapshot()
    assert now.particles is None
    view.show_state(now)
    assert not view.particles.isVisible()
    assert re.search(message, now.errors["/nav/particles"]), now.errors  # the reason, under the topic
    # the next good cloud is drawn and clears the topic's error
    state.feed("/nav/particles", codec.encode(GOOD_CLOUD), 2.0)
    now = state.snapshot()
    view.show_state(now)
    assert view.particles.isVisible() and "/nav/particles" not in now.errors
    # a bad one after it leaves the good one drawn
    state.feed("/nav/particles", codec.encode(bad), 3.0)
    kept, drawn = state.snapshot().particles, now.particles
    assert kept is not None and drawn is not None and np.array_equal(kept, drawn)
    assert "/nav/particles" in state.snapshot().errors


GOOD_AREA = {"stamp": 1.0, "frame": "map", "mode": "2.5D", "x": 2.0, "y": 2.0, "width": 4.0, "depth": 4.0,
             "height": 2.0, "reason": "start", "since": 1.0, "objects": ["drop_table"], "avoided": []}  # fmt: skip


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"width": math.nan}, "a zoom-map area's width must be finite numbers, got nan"),
        ({"x": "2"}, "a zoom-map area's x must be finite numbers, got '2'"),
        ({"depth": None}, "a zoom-map area needs x, y, width and depth"),
        ({"width": -4.0}, r"a zoom-map area of -4 × 4 m is empty"),
        ({"frame": "odom"}, "a zoom-map area in frame 'odom', not the map's"),
    ],
)
def test_a_malformed_zoom_area_is_refused_and_the_replay_goes_on(
    qtbot: QtBot, system: System, change: dict[str, Any], message: str
) -> None:
    assert system.environment is not None
    state = LiveState(feeds_of(system), system.environment.zoom)
    view = view_of(qtbot, system)
    bad = {k: v for k, v in {**GOOD_AREA, **change}.items() if v is not None}
    state.feed("/nav/zoom", codec.encode(bad), 1.0)
    state.feed("/nav/pose", estimate(5.0, 3.0, 0.0), 1.0)
    now = state.snapshot()
    assert message in now.errors["/nav/zoom"]
    assert now.zoom is not None and now.zoom.replayed and (now.zoom.x, now.zoom.y) == (5.0, 3.0)  # not the bad one
    view.show_state(now)
    assert view.zoom_label.text() == "zoom map (replayed)"
    state.feed("/nav/zoom", codec.encode(GOOD_AREA), 2.0)
    now = state.snapshot()
    assert now.zoom is not None and not now.zoom.replayed and "/nav/zoom" not in now.errors


def test_a_zoom_area_that_is_not_a_message_is_refused(system: System) -> None:
    state = LiveState(feeds_of(system))
    state.feed("/nav/zoom", codec.encode([2.0, 2.0, 4.0, 4.0]), 1.0)
    assert state.snapshot().errors["/nav/zoom"] == "a zoom-map area must be a message, got list"


def test_an_estimate_with_a_bad_cloud_keeps_its_pose_and_names_the_cloud(system: System) -> None:
    state = LiveState(feeds_of(system))
    state.feed("/nav/pose", estimate(2.0, 3.0, 0.1, particles=np.array([[1.0, math.nan]])), 1.0)
    now = state.snapshot()
    assert now.estimate["turtlebot"] == (2.0, 3.0, 0.1) and now.particles is None
    assert "not finite" in now.errors["/nav/pose"]
    state.feed("/nav/pose", estimate(2.1, 3.0, 0.1), 2.0)  # a good estimate clears it
    assert "/nav/pose" not in state.snapshot().errors
