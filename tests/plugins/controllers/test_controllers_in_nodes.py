"""The new controller kinds inside a running node, on the loopback plant: a PID whose optional part
is friction-feedforward closes a speed loop, and diff-drive-odometry integrates two simulated wheels."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

import ckmconf
from ckmconf.model import System
from runtime.kernel.node import NodeRuntime
from runtime.network import Sample, Transport
from runtime.verification.verify import verify
from tests.runtime.kernel.test_node import nodes, transport, until  # noqa: F401  (fixtures)

OPTIONAL = """<System xmlns="urn:ckm:1" version="1.0" name="feedforward">
  <Node name="n">
    <HWChannel name="y" direction="in"><Param name="plant" value="p"/></HWChannel>
    <HWChannel name="u" direction="out" min="-1" max="1">
      <Param name="plant" value="p"/><Param name="gain" value="2"/><Param name="timeConstant" value="0.2"/>
    </HWChannel>
    <Topic name="y" type="float64" scope="internal"/>
    <Topic name="r" type="float64" scope="internal"/>
    <Topic name="u" type="float64" scope="internal" lifespan="0.05"/>
    <Sensor name="y" channel="y" topic="y" period="0.01"/>
    <Controller name="pid" kind="pid" period="0.01" horizon="20">
      <Param name="kp" value="0.8"/><Param name="ki" value="2"/>
      <Input topic="y" role="measure"/><Input topic="r" role="setpoint"/><Output topic="u"/>
      <Optional kind="friction-feedforward" minIdle="0.2">
        <Param name="kp" value="0.8"/><Param name="ki" value="2"/><Param name="coulomb" value="0.05"/>
      </Optional>
    </Controller>
    <Actuator name="u" channel="u" topic="u" min="-1" max="1" safeValue="0"/>
  </Node>
</System>"""

ODOMETRY = """<System xmlns="urn:ckm:1" version="1.0" name="odometry">
  <MessageType name="Pose2D">
    <Field name="x" type="float64"/><Field name="y" type="float64"/><Field name="yaw" type="float64"/>
  </MessageType>
  <MessageType name="Twist">
    <Field name="linear" type="float64"/><Field name="angular" type="float64"/>
  </MessageType>
  <MessageType name="Odometry">
    <Field name="stamp" type="time"/><Field name="pose" type="Pose2D"/><Field name="twist" type="Twist"/>
    <Field name="dispersion" type="float64"/>
  </MessageType>
  <Node name="base">
    <HWChannel name="left_encoder" direction="in"><Param name="plant" value="left"/></HWChannel>
    <HWChannel name="right_encoder" direction="in"><Param name="plant" value="right"/></HWChannel>
    <HWChannel name="left_motor" direction="out" min="-1" max="1">
      <Param name="plant" value="left"/><Param name="gain" value="1"/><Param name="timeConstant" value="0.05"/>
    </HWChannel>
    <HWChannel name="right_motor" direction="out" min="-1" max="1">
      <Param name="plant" value="right"/><Param name="gain" value="1"/><Param name="timeConstant" value="0.05"/>
    </HWChannel>
    <Topic name="left_speed" type="float64" scope="internal"/>
    <Topic name="right_speed" type="float64" scope="internal"/>
    <Topic name="left_cmd" type="float64" scope="internal"/>
    <Topic name="right_cmd" type="float64" scope="internal"/>
    <Topic name="odom" type="Odometry"/>
    <!-- The constant wheel commands need an Input; nobody publishes this one (a missing set point is allowed). -->
    <Topic name="enable" type="float64" scope="internal"/>
    <Sensor name="left" channel="left_encoder" topic="left_speed" period="0.01"/>
    <Sensor name="right" channel="right_encoder" topic="right_speed" period="0.01"/>
    <Controller name="left_drive" kind="constant" period="0.02"><Param name="value" value="0.2"/>
      <Input topic="enable" role="setpoint"/><Output topic="left_cmd"/></Controller>
    <Controller name="right_drive" kind="constant" period="0.02"><Param name="value" value="0.3"/>
      <Input topic="enable" role="setpoint"/><Output topic="right_cmd"/></Controller>
    <Controller name="odometry" kind="diff-drive-odometry" period="0.02">
      <Param name="wheelBase" value="0.25"/>
      <Input topic="left_speed" role="left"/><Input topic="right_speed" role="right"/>
      <Output topic="odom"/>
    </Controller>
    <Actuator name="left_motor" channel="left_motor" topic="left_cmd" min="-1" max="1" safeValue="0"/>
    <Actuator name="right_motor" channel="right_motor" topic="right_cmd" min="-1" max="1" safeValue="0"/>
  </Node>
</System>"""


def load(tmp_path: Path, text: str) -> System:
    path = tmp_path / "system.xml"
    path.write_text(text)
    system = ckmconf.load(path)
    assert verify(system) == []  # every kind, Param and message type checks before the build
    return system


def test_friction_feedforward_runs_as_the_pids_optional_part(
    nodes: Callable[[System, str], NodeRuntime], transport: Transport, tmp_path: Path  # noqa: F811
) -> None:
    node = nodes(load(tmp_path, OPTIONAL), "n")
    reference = transport.publisher(node.topic("r"))
    speed = transport.subscribe(node.topic("y"))
    control = node.controllers["pid"]

    def settled() -> bool:
        reference.publish(0.5)
        sample = speed.latest()
        return sample is not None and abs(sample.value - 0.5) < 0.02 and control.optional_used > 20

    assert until(settled, timeout=15)
    assert node.statistics()["tasks"]["n.pid"]["failures"] == 0


def test_odometry_integrates_two_simulated_wheels(
    nodes: Callable[[System, str], NodeRuntime], transport: Transport, tmp_path: Path  # noqa: F811
) -> None:
    node = nodes(load(tmp_path, ODOMETRY), "base")
    received: list[Sample] = []
    transport.subscribe(node.topic("odom"), received.append)

    def moving() -> bool:
        return len(received) > 20 and received[-1].value["twist"]["linear"] > 0.249

    assert until(moving, timeout=15)
    first, last = received[5].value, received[-1].value
    assert last["twist"]["angular"] == pytest.approx(0.1 / 0.25, abs=0.01)
    assert last["pose"]["yaw"] > first["pose"]["yaw"] > 0.0 and last["dispersion"] > first["dispersion"] > 0.0
    assert node.statistics()["tasks"]["base.odometry"]["failures"] == 0


def test_verify_refuses_a_number_topic_as_diff_drives_velocity_command(tmp_path: Path) -> None:
    text = ODOMETRY.replace(
        '<Controller name="odometry"',
        '<Controller name="kinematics" kind="diff-drive" period="0.02" active="false">'
        '<Param name="wheelBase" value="0.2"/>'
        '<Input topic="left_speed" role="setpoint"/><Output topic="left_cmd"/><Output topic="right_cmd"/>'
        '</Controller>\n    <Controller name="odometry"',
    )
    path = tmp_path / "system.xml"
    path.write_text(text)
    (error,) = verify(ckmconf.load(path))
    assert "controller 'kinematics' (diff-drive) reads dicts of fields as 'setpoint'" in str(error)
    assert "of type float64" in str(error) and str(error).startswith(f"{path}:")
