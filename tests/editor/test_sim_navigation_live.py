"""End to end (issue K.5, D215-D216): the Navigation Smart Resource running its amcl-navigation plugin
on the lab's map, fed a scan and odometry over a private loopback network, publishes its pose, its
particle cloud and its zoom-map area; the Monitor tab's live map, subscribed to the use case's topics,
draws the published cloud and area around the robot, not a replay."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from pytestqt.qtbot import QtBot

from ckmconf.loader import load
from editor.views.sim_map import SimLivePanel, to_scene
from runtime.network import TopicQoS, Transport
from runtime.resources import codec
from runtime.resources.resource import SmartResourceRuntime
from tests.plugins.navigation.test_amcl import odometry
from tests.plugins.navigation.test_amcl import scan as laser_scan
from tests.plugins.navigation.test_live import ENVIRONMENT, HOME, lab, lab_grid
from tests.runtime.resources.conftest import pair  # noqa: F401 (fixture: two started loopback transports)

SYSTEM = f"""<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="navigation-live">
  <Topic name="/scan" type="bytes"/><Topic name="/base/odom" type="bytes"/>
  <Topic name="/nav/pose" type="bytes"/>
  <Topic name="/nav/particles" type="bytes"/><Topic name="/nav/zoom" type="bytes"/>
  <Node name="pc" kind="service"/>
  <SmartResource name="Navigation" node="pc">
    <Plugin name="amcl" kind="amcl-navigation">
      <Param name="environment" value="{ENVIRONMENT}"/>
      <Param name="particles" value="500"/>
      <Param name="initialPose" value="1.5 1.5 0.785"/>
      <Param name="initialSpread" value="0.2 0.1"/>
      <Param name="robotRadius" value="0.18"/><Param name="robotHeight" value="0.45"/>
      <Param name="laserPose" value="0.10 0 0"/><Param name="laserHeight" value="0.14"/>
    </Plugin>
    <Profile name="RUN" output="amcl"><Use plugin="amcl"/></Profile>
    <Service name="AMCL" rate="0.2" performance="localization_dispersion">
      <Input name="scan" topic="/scan"/>
      <Input name="odom" topic="/base/odom"/>
      <Output name="pose" topic="/nav/pose"/>
      <Output name="particles" topic="/nav/particles"/>
      <Output name="zoom" topic="/nav/zoom"/>
      <QualityMeasure name="localization_dispersion" kind="qoc" domain="performance" source="dispersion" unit="m"/>
      <Scenario name="RUN" profile="RUN"><Policy measure="localization_dispersion" upper="5"/></Scenario>
    </Service>
  </SmartResource>
</System>
"""


def test_the_monitor_tab_draws_the_navigations_published_cloud_and_zoom_area(
    qtbot: QtBot, tmp_path: Path, pair: tuple[Transport, Transport]  # noqa: F811 (the imported fixture)
) -> None:
    server, editor_side = pair
    (tmp_path / "system.xml").write_text(SYSTEM)
    record = load(tmp_path / "system.xml").resource("Navigation")
    assert record is not None
    runtime = SmartResourceRuntime(record, server, announce_period=0.2)
    panel = SimLivePanel()
    qtbot.addWidget(panel)
    scans = editor_side.publisher(TopicQoS("/scan", "ckm/service-data", reliability="best-effort"))
    odom = editor_side.publisher(TopicQoS("/base/odom", "ckm/service-data", reliability="best-effort"))
    sweep, still = codec.encode(laser_scan(lab_grid(), HOME)), codec.encode(odometry((0.0, 0.0, 0.0)))
    runtime.setup()
    runtime.start()
    try:
        panel.start(lab(), editor_side)  # the use case's feeds: /nav/pose, /nav/particles, /nav/zoom
        for topic in ("/scan", "/base/odom"):
            assert editor_side.wait_for_subscribers(topic, 1, 20.0), topic
        view = panel.map

        def drawn() -> bool:
            scans.publish(sweep)  # the robot stands at HOME: the same sweep, the odometry at rest
            odom.publish(still)
            panel.refresh()
            return view.particles.isVisible() and view.zoom_label.text().startswith("zoom map (start")

        deadline = time.monotonic() + 30.0
        while not drawn() and time.monotonic() < deadline:
            qtbot.wait(100)
        assert drawn(), f"no published cloud and area drawn within 30 s: {panel.notes.text()!r}"
        assert panel.state is not None
        now = panel.state.snapshot()
        assert now.errors == {} and now.particles is not None and len(now.particles) == 200
        assert np.linalg.norm(np.median(now.particles, axis=0) - HOME[:2]) < 0.2  # the cloud is on the robot
        assert now.zoom is not None and not now.zoom.replayed and now.zoom.objects
        assert np.hypot(now.zoom.x - HOME[0], now.zoom.y - HOME[1]) < 0.2  # centred on the first estimate
        centre = view.zoom.rect().center()
        assert (centre - to_scene(now.zoom.x, now.zoom.y)).manhattanLength() < 1e-6
        assert "Particles" not in panel.notes.text() and "Unreadable" not in panel.notes.text()
    finally:
        panel.stop()
        runtime.stop()
