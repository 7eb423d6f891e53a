"""The three services in real Smart Resource runtimes on a loopback transport, wired as the use case
wires them (Scan → /scan, Displacement ↔ Navigation over /base/odom and /base/path): a raw sweep and
wheel odometry in, the goal configured by a client, then the pose, the status, a path and a wheel
command out, each service's measure recorded; a bad goal is refused to the client with the reason."""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from ckmconf.loader import load
from runtime.network import TopicQoS, Transport
from runtime.resources import codec
from runtime.resources.client import ServiceClient, ServiceDirectory, ServiceError
from runtime.resources.resource import SmartResourceRuntime
from tests import waiting
from tests.runtime.resources.conftest import pair  # noqa: F401 (fixture: two started loopback transports)

from .loop import room
from .test_amcl import ANGLES, LASER, grid
from .test_amcl import scan as laser_scan

SCENARIO = '<QualityMeasure name="deadline" kind="qos" domain="temporal" source="deadline" unit="s"/>' \
           '<Scenario name="RUN" profile="RUN"><Policy measure="deadline" upper="5"/></Scenario>'
SYSTEM = f"""<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="navigation-runtime">
  <Topic name="hokuyo_raw" type="bytes"/><Topic name="/scan" type="bytes"/>
  <Topic name="/kobuki/wheel_odom" type="bytes"/><Topic name="/kobuki/cmd_vel" type="bytes"/>
  <Topic name="/base/odom" type="bytes"/><Topic name="/base/path" type="bytes"/>
  <Topic name="/base/move_goal" type="bytes"/><Topic name="/base/move_status" type="bytes"/>
  <Topic name="/nav/pose" type="bytes"/><Topic name="/nav/status" type="bytes"/>
  <Node name="pc" kind="service"/>
  <SmartResource name="LaserSensor" node="pc">
    <Plugin name="scan" kind="laser-scan">
      <Param name="fov" value="4.1888"/><Param name="rangeMin" value="0.02"/><Param name="rangeMax" value="5.6"/>
    </Plugin>
    <Profile name="RUN" output="scan"><Use plugin="scan"/></Profile>
    <Service name="Scan" rate="0.05" performance="scan_time">
      <Input name="raw" topic="hokuyo_raw"/>
      <Output name="scan" topic="/scan"/>
      <Parameter name="resolution" type="float" default="0.00614" min="0.00614" max="0.0614"/>
      <QualityMeasure name="scan_time" kind="qos" domain="temporal" source="scan_time" unit="s"/>
      {SCENARIO}
    </Service>
  </SmartResource>
  <SmartResource name="MobileBase" node="pc">
    <Plugin name="displacement" kind="base-displacement"/>
    <Profile name="RUN" output="displacement"><Use plugin="displacement"/></Profile>
    <Service name="Displacement" rate="0.05" performance="odometry_dispersion">
      <Input name="path" topic="/base/path"/>
      <Input name="move_goal" topic="/base/move_goal"/>
      <Input name="wheel_odom" topic="/kobuki/wheel_odom"/>
      <Output name="odom" topic="/base/odom"/>
      <Output name="move_status" topic="/base/move_status"/>
      <Output name="wheel_cmd" topic="/kobuki/cmd_vel"/>
      <Parameter name="speed" type="float" default="0.3" min="0.05" max="0.7"/>
      <QualityMeasure name="odometry_dispersion" kind="qoc" domain="performance" source="dispersion" unit="m"/>
      {SCENARIO}
    </Service>
  </SmartResource>
  <SmartResource name="Navigation" node="pc">
    <Plugin name="amcl" kind="amcl-navigation">
      <Param name="environment" value="room.xml"/>
      <Param name="particles" value="500"/>
      <Param name="initialPose" value="1 1.8 0"/>
      <Param name="initialSpread" value="0.1 0.05"/>
      <Param name="robotRadius" value="0.18"/><Param name="robotHeight" value="0.45"/>
      <Param name="laserPose" value="0.10 0 0"/><Param name="laserHeight" value="0.14"/>
    </Plugin>
    <Profile name="RUN" output="amcl"><Use plugin="amcl"/></Profile>
    <Service name="AMCL" rate="0.2" performance="localization_dispersion">
      <Input name="scan" topic="/scan"/>
      <Input name="odom" topic="/base/odom"/>
      <Output name="pose" topic="/nav/pose"/>
      <Output name="status" topic="/nav/status"/>
      <Output name="path" topic="/base/path"/>
      <Parameter name="goal" type="string" default=""/>
      <QualityMeasure name="localization_dispersion" kind="qoc" domain="performance" source="dispersion" unit="m"/>
      {SCENARIO}
    </Service>
  </SmartResource>
</System>
"""


until = functools.partial(waiting.until, timeout=15.0, interval=0.02)  # this file's polling and bound


def collect(received: list[Any]) -> Callable[[Any], None]:
    """A subscription callback keeping each sample's decoded value."""
    return lambda sample: received.append(codec.decode(sample.value))


def test_the_services_run_wired_in_smart_resource_runtimes(
    tmp_path: Path, pair: tuple[Transport, Transport]  # noqa: F811 (the imported fixture)
) -> None:
    server, remote = pair
    (tmp_path / "system.xml").write_text(SYSTEM)
    world = grid(room(tmp_path))
    system = load(tmp_path / "system.xml")
    records = [system.resource(name) for name in ("LaserSensor", "MobileBase", "Navigation")]
    runtimes = [SmartResourceRuntime(r, server, announce_period=0.2) for r in records if r is not None]
    assert len(runtimes) == 3
    raw = laser_scan(world, (1.0, 1.8, 0.0))["ranges"]  # the sweep the robot's lidar sees, as the sensor sends it
    assert raw.size == ANGLES.size and LASER[0] == 0.10
    seen: dict[str, list[Any]] = {t: [] for t in ("/nav/status", "/base/path", "/kobuki/cmd_vel", "/scan")}
    for topic, received in seen.items():
        remote.subscribe(TopicQoS(topic, "ckm/service-data", history=16), collect(received))
    lidar = remote.publisher(TopicQoS("hokuyo_raw", "ckm/raw", reliability="best-effort"))
    wheels = remote.publisher(TopicQoS("/kobuki/wheel_odom", "ckm/raw", reliability="best-effort"))
    for runtime in runtimes:
        runtime.setup()
        runtime.start()
    try:
        for topic in ("hokuyo_raw", "/kobuki/wheel_odom"):
            assert remote.wait_for_subscribers(topic, 1, 10)
        entry = ServiceDirectory(remote).wait_for("Navigation", "AMCL", timeout=10)
        with ServiceClient(remote, entry, "nav-behavior") as client:
            client.connect(timeout=10)
            client.configure(parameters={"goal": "Target"}, timeout=10)

            def feed() -> bool:
                stamp = time.time()
                ranges = np.where(np.isinf(raw), 5.6, np.where(np.isfinite(raw), raw, 5.6)).astype(np.float32)
                lidar.publish(codec.encode({"stamp": stamp, "angle_min": 0.0, "angle_max": 0.0, "angle_increment": 0.0,
                               "time_increment": 0.0, "scan_time": 0.0, "range_min": 0.0, "range_max": 0.0,
                               "ranges": ranges, "intensities": np.zeros(0, np.float32)}))
                wheels.publish(codec.encode({"stamp": stamp, "pose": {"x": 0.0, "y": 0.0, "yaw": 0.0},
                                             "twist": {"linear": 0.0, "angular": 0.0}, "dispersion": 0.0}))
                return any(s["state"] == "active" for s in seen["/nav/status"]) and any(
                    c["linear"] > 0 or abs(c["angular"]) > 0 for c in seen["/kobuki/cmd_vel"])

            assert until(feed), (seen["/nav/status"][-1:], seen["/kobuki/cmd_vel"][-1:])
            status = next(s for s in seen["/nav/status"] if s["state"] == "active")
            assert status["goal"] == "Target" and status["path_length"] > 3.0
            assert any(p["points"] and p["frame"] == "odom" for p in seen["/base/path"])
            assert seen["/scan"][-1]["range_max"] == 5.6 and seen["/scan"][-1]["ranges"].size == ANGLES.size
            with pytest.raises(ServiceError, match="'Kitchen' is neither an Area of environment 'nav-room'"):
                client.configure(parameters={"goal": "Kitchen"}, timeout=10)
        measures = {name: value for runtime in runtimes for instance in runtime.instances()
                    for name, value in instance.measures.last.items()}
        assert {"scan_time", "odometry_dispersion", "localization_dispersion"} <= set(measures)
        assert 0 < measures["localization_dispersion"] < 1.0 and measures["scan_time"] > 0
    finally:
        for runtime in runtimes:
            runtime.stop()
