"""The station arm's arm-motion and gripper services in a system of its own: ``verify`` accepts the
pick-object and place-object behaviors bound to them and refuses a ``<Uses>`` bound to a service of
another interface at its FILE:LINE:COL; the gripper service runs in a SmartResourceRuntime on a
loopback transport (command and joint states as one multi-input stream, trajectory and status out,
the ``holding`` measure)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import ckmconf
from ckmconf.model import System
from plugins.manipulation.gripper import ParallelGripper
from runtime.network import TopicQoS, Transport
from runtime.registry import Registry
from runtime.resources import codec
from runtime.resources.resource import SmartResourceRuntime
from runtime.verification.verify import verify
from tests.conftest import CONFIGS
from tests.runtime.resources.conftest import pair  # noqa: F401  (the transport-pair fixture)
from tests.waiting import until

POSES = CONFIGS / "examples" / "models" / "station_arm_poses.yml"


def system_text(gripper_alias_service: str = "Station.Gripper") -> str:
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="station-cell">
  <MessageType name="ArmTarget">
    <Field name="x" type="float64" unit="m"/><Field name="y" type="float64" unit="m"/>
    <Field name="z" type="float64" unit="m"/><Field name="pitch" type="float64" unit="rad"/>
  </MessageType>
  <MessageType name="ArmGoal">
    <Field name="id" type="int64"/><Field name="group" type="string"/><Field name="pose" type="string"/>
    <Field name="target" type="ArmTarget"/><Field name="contact" type="bool"/>
  </MessageType>
  <MessageType name="GripperCommand">
    <Field name="id" type="int64"/><Field name="action" type="string"/><Field name="position" type="float64"/>
    <Field name="max_effort" type="float64" unit="N"/>
  </MessageType>
  <Topic name="/arm/goal" type="ArmGoal"/>
  <Topic name="/arm/joint_states" type="bytes"/>
  <Topic name="/arm/trajectory" type="bytes"/>
  <Topic name="/arm/status" type="bytes"/>
  <Topic name="/jaw/command" type="GripperCommand"/>
  <Topic name="/jaw/joint_states" type="bytes"/>
  <Topic name="/jaw/trajectory" type="bytes"/>
  <Topic name="/jaw/status" type="bytes"/>
  <Node name="cell" kind="service"/>
  <SmartResource name="Station" node="cell">
    <Plugin name="arm" kind="arm-poses"><Param name="model" value="station_arm"/>
      <Param name="poses" value="{POSES}"/><Param name="gripper" value="false"/>
      <Param name="joints" value="turret_joint shoulder_joint elbow_joint"/></Plugin>
    <Plugin name="jaw" kind="parallel-gripper"><Param name="model" value="station_arm"/>
      <Param name="joints" value="left_finger_joint"/><Param name="settle" value="0.2"/></Plugin>
    <Profile name="ARM" output="arm"><Use plugin="arm"/></Profile>
    <Profile name="JAW" output="jaw"><Use plugin="jaw"/></Profile>
    <Service name="Arm" performance="active">
      <Input name="goal" topic="/arm/goal"/>
      <Input name="joint_states" topic="/arm/joint_states"/>
      <Output name="trajectory" topic="/arm/trajectory"/>
      <Output name="status" topic="/arm/status"/>
      <QualityMeasure name="active" kind="qos" domain="performance" source="active"/>
      <Scenario name="ARM" profile="ARM"><Policy measure="active" lower="1" probability="0.99"/></Scenario>
    </Service>
    <Service name="Gripper" performance="active">
      <Input name="command" topic="/jaw/command"/>
      <Input name="joint_states" topic="/jaw/joint_states"/>
      <Output name="trajectory" topic="/jaw/trajectory"/>
      <Output name="status" topic="/jaw/status"/>
      <QualityMeasure name="active" kind="qos" domain="performance" source="active"/>
      <QualityMeasure name="holding" kind="qoc" domain="performance" source="holding"/>
      <Scenario name="JAW" profile="JAW"><Policy measure="active" lower="1" probability="0.99"/></Scenario>
    </Service>
  </SmartResource>
  <Behavior name="PICK" kind="pick-object" timeout="30">
    <Param name="approach" value="0.5 0 0.95"/><Param name="grasp" value="0.5 0 0.80"/>
    <Param name="lift" value="home"/>
    <Uses service="Station.Arm" as="arm"/>
    <Uses service="{gripper_alias_service}" as="gripper"/>
    <Output name="arm_goal" topic="/arm/goal"/>
    <Output name="gripper_command" topic="/jaw/command"/>
  </Behavior>
  <Behavior name="PLACE" kind="place-object" timeout="30">
    <Param name="above" value="0.5 0 0.95"/><Param name="place" value="0.5 0 0.81"/>
    <Param name="retreat" value="home"/>
    <Uses service="Station.Arm" as="arm"/>
    <Uses service="Station.Gripper" as="gripper"/>
    <Output name="arm_goal" topic="/arm/goal"/>
    <Output name="gripper_command" topic="/jaw/command"/>
  </Behavior>
</System>
"""


def _load(tmp_path: Path, text: str) -> System:
    path = tmp_path / "station.xml"
    path.write_text(text, encoding="utf-8")
    return ckmconf.load(path)


def test_verify_accepts_the_station_s_pick_and_place_and_refuses_a_gripper_bound_to_the_arm(tmp_path: Path) -> None:
    registry = Registry(packages=("ckm",))
    assert [str(e) for e in verify(_load(tmp_path, system_text()), registry)] == []
    text = system_text("Station.Arm")
    wrong = verify(_load(tmp_path, text), registry)
    assert [e.message for e in wrong] == [
        "behavior 'PICK' (pick-object) uses 'Station.Arm' as 'gripper', which must be a gripper service, not an "
        "arm-motion one"]
    uses_line = text.splitlines().index('    <Uses service="Station.Arm" as="gripper"/>') + 1
    assert wrong[0].file.endswith("station.xml") and (wrong[0].line, wrong[0].column) == (uses_line, 11)


def collect(received: list[Any]) -> Callable[[Any], None]:
    return lambda sample: received.append(codec.decode(sample.value))


def test_the_gripper_service_runs_in_a_smart_resource_runtime(
    tmp_path: Path, pair: tuple[Transport, Transport]  # noqa: F811
) -> None:
    server, remote = pair
    record = _load(tmp_path, system_text()).resource("Station")
    assert record is not None
    runtime = SmartResourceRuntime(record, server, announce_period=0.2)
    seen: dict[str, list[Any]] = {t: [] for t in ("/jaw/trajectory", "/jaw/status")}
    for topic, received in seen.items():
        remote.subscribe(TopicQoS(topic, "ckm/service-data", history=16), collect(received))
    publish = {t: remote.publisher(TopicQoS(t, "ckm/raw")) for t in ("/jaw/command", "/jaw/joint_states")}
    runtime.setup()
    runtime.start()
    try:
        for topic in publish:
            assert remote.wait_for_subscribers(topic, 1, 10)
        plugin = runtime.streams["jaw"].topology.plugins["jaw"]
        assert isinstance(plugin, ParallelGripper)
        finger = [0.17]  # open; the command closes it onto a parcel's side at 0.12 m

        def feed() -> bool:
            publish["/jaw/command"].publish(codec.encode({"id": 4, "action": "close", "max_effort": 25.0}))
            publish["/jaw/joint_states"].publish(codec.encode({"stamp": time.time(), "name": [], "position": finger}))
            return bool(seen["/jaw/trajectory"]) and bool(seen["/jaw/status"])

        assert until(feed)
        points = seen["/jaw/trajectory"][0]["points"]
        assert points[1]["positions"] == [0.0] and points[1]["effort"] == [25.0]
        finger = [0.12]

        def holding() -> bool:
            feed()
            return any(s["state"] == "holding" for s in seen["/jaw/status"])

        assert until(holding, timeout=15.0), seen["/jaw/status"][-1:]
        assert len(seen["/jaw/trajectory"]) == 1  # one trajectory for the command, however often it is resent
        measures = {name: value for instance in runtime.instances() for name, value in instance.measures.last.items()}
        assert measures["holding"] == 1.0
    finally:
        runtime.stop()
