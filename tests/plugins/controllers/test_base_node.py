"""A Kobuki-like light node on loopback wheels: Twist → diff-drive → wheel PIDs → motors, a switch
to ramp-stop when the commands go stale, and odometry — the multi-output protocol in a running node.

It needs a control service that calls ``step_outputs`` (D91); on one that does not, the diff-drive
task fails at its first period and the test is reported as an expected failure at once."""

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

BASE = """<System xmlns="urn:ckm:1" version="1.0" name="base">
  <MessageType name="Twist"><Field name="linear" type="float64"/><Field name="angular" type="float64"/></MessageType>
  <MessageType name="Pose2D">
    <Field name="x" type="float64"/><Field name="y" type="float64"/><Field name="yaw" type="float64"/>
  </MessageType>
  <MessageType name="Odometry">
    <Field name="stamp" type="time"/><Field name="pose" type="Pose2D"/><Field name="twist" type="Twist"/>
    <Field name="dispersion" type="float64"/>
  </MessageType>
  <Node name="kobuki">
    <HWChannel name="left_encoder" direction="in"><Param name="plant" value="left"/></HWChannel>
    <HWChannel name="right_encoder" direction="in"><Param name="plant" value="right"/></HWChannel>
    <HWChannel name="left_motor" direction="out" min="-1" max="1">
      <Param name="plant" value="left"/><Param name="gain" value="0.7"/><Param name="timeConstant" value="0.1"/>
    </HWChannel>
    <HWChannel name="right_motor" direction="out" min="-1" max="1">
      <Param name="plant" value="right"/><Param name="gain" value="0.7"/><Param name="timeConstant" value="0.1"/>
    </HWChannel>
    <Topic name="/cmd_vel" type="Twist" lifespan="0.2"/>
    <Topic name="left_speed" type="float64" scope="internal"/>
    <Topic name="right_speed" type="float64" scope="internal"/>
    <Topic name="left_setpoint" type="float64" scope="internal" lifespan="0.1"/>
    <Topic name="right_setpoint" type="float64" scope="internal" lifespan="0.1"/>
    <Topic name="left_cmd" type="float64" scope="internal" lifespan="0.05"/>
    <Topic name="right_cmd" type="float64" scope="internal" lifespan="0.05"/>
    <Topic name="/odom" type="Odometry"/>
    <Sensor name="left_wheel" channel="left_encoder" topic="left_speed" period="0.01"/>
    <Sensor name="right_wheel" channel="right_encoder" topic="right_speed" period="0.01"/>
    <Controller name="diffdrive" kind="diff-drive" period="0.02">
      <Param name="wheelBase" value="0.23"/><Param name="maxLinear" value="0.7"/>
      <Input topic="/cmd_vel" role="setpoint"/><Output topic="left_setpoint"/><Output topic="right_setpoint"/>
      <Switch to="hold_still" when="stale('/cmd_vel')"/>
    </Controller>
    <Controller name="hold_still" kind="ramp-stop" period="0.02" active="false">
      <Param name="deceleration" value="0.5"/>
      <Input topic="left_speed" role="measure"/><Input topic="right_speed" role="measure"/>
      <Output topic="left_setpoint"/><Output topic="right_setpoint"/>
      <Switch to="diffdrive" when="not stale('/cmd_vel') and elapsed &gt; 0.2"/>
    </Controller>
    <Controller name="left_pid" kind="pid" period="0.01">
      <Param name="kp" value="1.2"/><Param name="ki" value="6"/><Param name="outputLimit" value="0.7"/>
      <Input topic="left_speed" role="measure"/><Input topic="left_setpoint" role="setpoint"/>
      <Output topic="left_cmd"/>
    </Controller>
    <Controller name="right_pid" kind="pid" period="0.01">
      <Param name="kp" value="1.2"/><Param name="ki" value="6"/><Param name="outputLimit" value="0.7"/>
      <Input topic="right_speed" role="measure"/><Input topic="right_setpoint" role="setpoint"/>
      <Output topic="right_cmd"/>
    </Controller>
    <Controller name="odometry" kind="diff-drive-odometry" period="0.02">
      <Param name="wheelBase" value="0.23"/>
      <Input topic="left_speed" role="measure"/><Input topic="right_speed" role="measure"/><Output topic="/odom"/>
    </Controller>
    <Actuator name="left_drive" channel="left_motor" topic="left_cmd" min="-0.7" max="0.7" safeValue="0">
      <Adaptation><Linear gain="1.428571"/></Adaptation>
    </Actuator>
    <Actuator name="right_drive" channel="right_motor" topic="right_cmd" min="-0.7" max="0.7" safeValue="0">
      <Adaptation><Linear gain="1.428571"/></Adaptation>
    </Actuator>
  </Node>
</System>"""


def test_twist_drives_the_wheels_and_a_stale_command_ramps_them_to_rest(
    nodes: Callable[[System, str], NodeRuntime], transport: Transport, tmp_path: Path  # noqa: F811
) -> None:
    path = tmp_path / "base.xml"
    path.write_text(BASE)
    system = ckmconf.load(path)
    assert verify(system) == []
    node = nodes(system, "kobuki")
    cmd = transport.publisher(node.topic("/cmd_vel"))
    left, right = transport.subscribe(node.topic("left_speed")), transport.subscribe(node.topic("right_speed"))
    odometry: list[Sample] = []
    transport.subscribe(node.topic("/odom"), odometry.append)

    cmd.publish({"linear": 0.3, "angular": 1.0})
    tasks = node.scheduler.tasks
    until(lambda: tasks["kobuki.diffdrive"].stats.releases > 2, timeout=5)
    assert node.statistics()["tasks"]["kobuki.diffdrive"]["failures"] == 0  # one value per output (D91)

    def turning() -> bool:
        cmd.publish({"linear": 0.3, "angular": 1.0})
        lw, rw = left.latest(), right.latest()
        return lw is not None and rw is not None and abs(lw.value - 0.185) < 0.01 and abs(rw.value - 0.415) < 0.01

    assert until(turning, timeout=15)
    assert node.controllers["diffdrive"].active
    assert odometry[-1].value["twist"]["angular"] == pytest.approx(1.0, abs=0.1)
    speeds: list[Sample] = []
    transport.subscribe(node.topic("right_setpoint"), speeds.append)
    def stopped() -> bool:
        sample = right.latest()
        return node.controllers["hold_still"].active and sample is not None and sample.value < 0.005

    assert until(stopped, timeout=15)
    ramp = [s.value for s in speeds if node.controllers["hold_still"].active]
    assert ramp and ramp[-1] == 0.0
    assert node.statistics()["tasks"]["kobuki.hold_still"]["failures"] == 0
