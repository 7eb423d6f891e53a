"""RoboticArm.MoveIt and Nao.NaoQi run by the Smart Resource runtime on a loopback transport: the
goal and the joint states reach plugin.arm-poses as one multi-input stream, its trajectory and
status come out on the Output topics, the ``speed`` Parameter reaches it, and ``active`` is measured;
the NaoQi bridge turns the camera and the two float64 head angles into image, head state and status."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ckmconf.loader import load
from plugins.manipulation.arm_poses import ArmPoses
from runtime.network import TopicQoS, Transport
from runtime.resources import codec
from runtime.resources.client import ServiceClient, ServiceDirectory
from runtime.resources.resource import SmartResourceRuntime
from tests.conftest import CONFIGS
from tests.plugins.manipulation.arm_loop import JOINTS
from tests.runtime.resources.conftest import pair  # noqa: F401  (the transport-pair fixture)
from tests.runtime.resources.test_service_api import until

POSES = CONFIGS / "usecase" / "models" / "arm_poses.yml"
SYSTEM = f"""<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="arm-and-nao">
  <Topic name="/arm/goal" type="bytes"/>
  <Topic name="/arm/joint_states" type="bytes"/>
  <Topic name="/arm/joint_trajectory" type="bytes"/>
  <Topic name="/arm/status" type="bytes"/>
  <Topic name="camera_raw" type="bytes"/>
  <Topic name="head_yaw_angle" type="float64"/>
  <Topic name="head_pitch_angle" type="float64"/>
  <Topic name="/nao/camera/image" type="bytes"/>
  <Topic name="/nao/head_state" type="bytes"/>
  <Topic name="/nao/status" type="bytes"/>
  <Node name="robot" kind="service"/>
  <SmartResource name="RoboticArm" node="robot">
    <Plugin name="moveit" kind="arm-poses"><Param name="poses" value="{POSES}"/><Param name="model" value="turtlebot"/>
      <Param name="joints" value="{JOINTS}"/></Plugin>
    <Profile name="MOVEIT" output="moveit"><Use plugin="moveit"/></Profile>
    <Service name="MoveIt" performance="active">
      <Input name="goal" topic="/arm/goal"/>
      <Input name="joint_states" topic="/arm/joint_states"/>
      <Output name="trajectory" topic="/arm/joint_trajectory"/>
      <Output name="status" topic="/arm/status"/>
      <Parameter name="speed" type="float" default="0.5" min="0.1" max="1.0"/>
      <QualityMeasure name="active" kind="qos" domain="performance" source="active"/>
      <Scenario name="MOVEIT" profile="MOVEIT"><Policy measure="active" lower="1" probability="0.99"/></Scenario>
    </Service>
  </SmartResource>
  <SmartResource name="Nao" node="robot">
    <Plugin name="naoqi" kind="naoqi-bridge"/>
    <Profile name="NAOQI" output="naoqi"><Use plugin="naoqi"/></Profile>
    <Service name="NaoQi" performance="available">
      <Input name="camera" topic="camera_raw"/>
      <Input name="head_yaw" topic="head_yaw_angle"/>
      <Input name="head_pitch" topic="head_pitch_angle"/>
      <Output name="image" topic="/nao/camera/image"/>
      <Output name="head_state" topic="/nao/head_state"/>
      <Output name="status" topic="/nao/status"/>
      <QualityMeasure name="available" kind="qos" domain="performance" source="available"/>
      <Scenario name="NAOQI" profile="NAOQI"><Policy measure="available" lower="1" probability="0.99"/></Scenario>
    </Service>
  </SmartResource>
</System>
"""


def collect(received: list[Any]) -> Callable[[Any], None]:
    return lambda sample: received.append(codec.decode(sample.value))


def test_the_arm_and_nao_services_run_in_smart_resource_runtimes(
    tmp_path: Path, pair: tuple[Transport, Transport]  # noqa: F811
) -> None:
    server, remote = pair
    (tmp_path / "system.xml").write_text(SYSTEM)
    system = load(tmp_path / "system.xml")
    records = [system.resource(name) for name in ("RoboticArm", "Nao")]
    runtimes = [SmartResourceRuntime(r, server, announce_period=0.2) for r in records if r is not None]
    seen: dict[str, list[Any]] = {t: [] for t in ("/arm/joint_trajectory", "/arm/status", "/nao/camera/image",
                                                  "/nao/head_state", "/nao/status")}
    for topic, received in seen.items():
        remote.subscribe(TopicQoS(topic, "ckm/service-data", history=16), collect(received))
    publish = {t: remote.publisher(TopicQoS(t, "ckm/raw")) for t in
               ("/arm/goal", "/arm/joint_states", "camera_raw", "head_yaw_angle", "head_pitch_angle")}
    for runtime in runtimes:
        runtime.setup()
        runtime.start()
    try:
        for topic in publish:
            assert remote.wait_for_subscribers(topic, 1, 10)
        plugin = runtimes[0].streams["moveit"].topology.plugins["moveit"]
        assert isinstance(plugin, ArmPoses)
        entry = ServiceDirectory(remote).wait_for("RoboticArm", "MoveIt", timeout=10)
        with ServiceClient(remote, entry, "pick-behavior") as client:
            client.connect(timeout=10)
            client.configure(parameters={"speed": 1.0}, timeout=10)  # Table 7.1's Speed
            assert plugin.speed == 1.0
            positions = np.zeros(5)

            def feed() -> bool:
                publish["/arm/goal"].publish(codec.encode({"id": 3, "group": "arm", "pose": "ready"}))
                states = {"stamp": time.time(), "name": [], "position": positions}
                publish["/arm/joint_states"].publish(codec.encode(states))
                frame = {"stamp": time.time(), "width": 4, "height": 2, "encoding": "rgb8", "data": bytes(24)}
                publish["camera_raw"].publish(codec.encode(frame))
                publish["head_yaw_angle"].publish(codec.encode(0.25))
                publish["head_pitch_angle"].publish(codec.encode(-0.1))
                return bool(seen["/arm/joint_trajectory"]) and bool(seen["/nao/status"]) and any(
                    s["available"] for s in seen["/nao/status"])

            assert until(feed), (seen["/arm/status"][-1:], seen["/nao/status"][-1:])
            trajectory = seen["/arm/joint_trajectory"][0]
            target = trajectory["points"][1]["positions"]
            assert target == list(plugin.solutions["ready"].joints)
            assert seen["/arm/status"][-1]["id"] == 3 and seen["/arm/status"][-1]["state"] == "moving"
            positions = np.array([*target, 0.0])

            def reached() -> bool:
                feed()
                return any(s["state"] == "reached" for s in seen["/arm/status"])

            assert until(reached)
        assert len(seen["/arm/joint_trajectory"]) == 1  # one trajectory for the goal, however often it is resent
        assert seen["/nao/head_state"][-1] == {"pan": 0.25, "tilt": -0.1}
        assert seen["/nao/camera/image"][-1]["data"] == bytes(24)
        measures = {name: value for runtime in runtimes for instance in runtime.instances()
                    for name, value in instance.measures.last.items()}
        assert measures["active"] == 1.0 and measures["available"] == 1.0
    finally:
        for runtime in runtimes:
            runtime.stop()
