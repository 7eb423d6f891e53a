"""A node built from XML runs its loops on the loopback plant, fails safe and switches bumplessly."""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

import ckmconf
from ckmconf.model import System
from runtime.kernel.node import NodeRuntime
from runtime.kernel.scheduler import Task
from runtime.network import Sample, Transport, open_transport
from tests import waiting
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network


@pytest.fixture
def transport() -> Iterator[Transport]:
    running = open_transport(private_network(), name="kernel-test")
    running.setup()
    running.start()
    yield running
    running.stop()


@pytest.fixture
def nodes(transport: Transport) -> Iterator[Callable[[System, str], NodeRuntime]]:
    made: list[NodeRuntime] = []

    def make(system: System, name: str) -> NodeRuntime:
        node = next(n for n in system.nodes if n.name == name)
        runtime = NodeRuntime(node, system, transport)
        made.append(runtime)
        runtime.setup()
        runtime.start()
        return runtime

    yield make
    for runtime in made:
        runtime.stop()


until = functools.partial(waiting.until, interval=0.01)  # this file's polling period


def example(name: str) -> System:
    return ckmconf.load(REPO / "configs" / "examples" / name)


def test_closed_loop_reaches_its_set_point(nodes: Callable[[System, str], NodeRuntime], transport: Transport) -> None:
    node = nodes(example("closed_loop.xml"), "motor-node")
    setpoint = transport.publisher(node.topic("setpoint"))
    speed = transport.subscribe(node.topic("speed"))

    def settled() -> bool:
        setpoint.publish(0.5)
        sample = speed.latest()
        return sample is not None and abs(sample.value - 0.5) < 0.02

    assert until(settled, timeout=15)
    stats = node.statistics()["tasks"]
    assert stats["motor-node.pid"]["releases"] > 10 and stats["motor-node.pid"]["failures"] == 0


def test_a_stale_sensor_plays_stored_actions_then_the_fallback_then_the_safe_value(
    nodes: Callable[[System, str], NodeRuntime], transport: Transport
) -> None:
    node = nodes(example("safe_actuation.xml"), "lift")
    target = transport.publisher(node.topic("/lift/target"))
    motor = node.actuators["motor"]
    assert until(lambda: (target.publish(1.0), motor.mode == "commanded")[1])
    node.scheduler.remove("lift.height")  # the sensor stops: the controller's input goes stale
    assert until(lambda: motor.mode == "safe", timeout=10)
    kinds = [e["kind"] for e in node.events]
    assert kinds.index("commands-stale") < kinds.index("safe-stop")
    assert motor.value == 0.0
    assert node.backends["motor"].read() == 0.0


def test_out_of_range_commands_never_reach_the_channel(
    nodes: Callable[[System, str], NodeRuntime], transport: Transport
) -> None:
    node = nodes(example("safe_actuation.xml"), "lift")
    node.scheduler.remove("lift.gpc")  # we command the actuator ourselves
    command = transport.publisher(node.topic("command"))
    motor = node.actuators["motor"]
    command.publish(0.1)
    assert until(lambda: motor.value is not None and motor.value > 0)
    before = node.backends["motor"].read()
    for value in (5.0, -7.0, float("nan"), 0.81):
        command.publish(value)
    assert until(lambda: motor.out_of_range == 4)  # a loaded machine may take longer than a few periods
    written = float(node.backends["motor"].read())  # type: ignore[arg-type]
    assert -0.8 <= written <= 0.8  # onOutOfRange="reject": the previous value holds
    assert written == before
    assert any(e["kind"] == "out-of-range" for e in node.events)


SWITCHING = """<System xmlns="urn:ckm:1" version="1.0" name="switching">
  <Node name="n">
    <HWChannel name="y" direction="in"><Param name="plant" value="p"/></HWChannel>
    <HWChannel name="u" direction="out" min="-10" max="10">
      <Param name="plant" value="p"/><Param name="gain" value="1"/><Param name="timeConstant" value="0.1"/>
    </HWChannel>
    <Topic name="y" type="float64" scope="internal"/>
    <Topic name="u" type="float64" scope="internal"/>
    <Topic name="r" type="float64" scope="internal"/>
    <Sensor name="y" channel="y" topic="y" period="0.01"/>
    <Controller name="a" kind="pid" period="0.01">
      <Param name="kp" value="0.5"/><Param name="ki" value="5"/>
      <Input topic="y" role="measure"/><Input topic="r" role="setpoint"/><Output topic="u"/>
    </Controller>
    <Controller name="b" kind="pid" period="0.01" active="false">
      <Param name="kp" value="2"/><Param name="ki" value="1"/>
      <Input topic="y" role="measure"/><Input topic="r" role="setpoint"/><Output topic="u"/>
    </Controller>
    <Actuator name="u" channel="u" topic="u" min="-10" max="10" safeValue="0"/>
  </Node>
</System>"""


def test_switching_controllers_keeps_the_output_continuous(
    nodes: Callable[[System, str], NodeRuntime], transport: Transport, tmp_path: Path
) -> None:
    path = tmp_path / "switching.xml"
    path.write_text(SWITCHING)
    node = nodes(ckmconf.load(path), "n")
    reference = transport.publisher(node.topic("r"))
    outputs: list[float] = []
    transport.subscribe(node.topic("u"), lambda sample: outputs.append(sample.value))
    assert until(lambda: (reference.publish(1.0), len(outputs) > 50)[1])
    node.switch("b")
    count = len(outputs)
    assert until(lambda: len(outputs) > count + 20)
    jump = abs(outputs[count] - outputs[count - 1])
    steps = [abs(b - a) for a, b in zip(outputs[count - 20 : count - 1], outputs[count - 19 : count], strict=True)]
    assert jump <= 3 * max(steps) + 0.05  # no bump: the new controller starts from the current output
    assert node.controllers["b"].active and not node.controllers["a"].active


OPTIONAL = SWITCHING.replace(
    '<Output topic="u"/>\n    </Controller>\n    <Controller name="b"',
    '<Output topic="u"/>\n      <Optional kind="gpc" minIdle="0.5"><Param name="gain" value="1"/>'
    '<Param name="timeConstant" value="0.1"/></Optional>\n    </Controller>\n    <Controller name="b"',
)


def test_the_optional_part_runs_only_while_the_scheduler_is_idle(
    nodes: Callable[[System, str], NodeRuntime], transport: Transport, tmp_path: Path
) -> None:
    path = tmp_path / "optional.xml"
    path.write_text(OPTIONAL)
    node = nodes(ckmconf.load(path), "n")
    reference = transport.publisher(node.topic("r"))
    control = node.controllers["a"]
    assert until(lambda: (reference.publish(1.0), control.optional_used > 20)[1])
    # A task keeping the scheduler 80 % busy leaves no room for an optional part needing 50 %.
    node.scheduler.add(Task("n.hog", 0.01, lambda: time.sleep(0.008)))
    task = node.scheduler.tasks["n.a"]
    skipped = task.stats.optional_skipped
    assert until(lambda: (reference.publish(1.0), task.stats.optional_skipped > skipped + 20)[1], timeout=15)
    node.scheduler.remove("n.hog")


def test_a_latched_safe_stop_ignores_late_commands(
    nodes: Callable[[System, str], NodeRuntime], transport: Transport
) -> None:
    node = nodes(example("safe_actuation.xml"), "lift")
    node.scheduler.remove("lift.gpc")
    motor = node.actuators["motor"]
    command = transport.publisher(node.topic("command"))
    assert until(lambda: (command.publish(0.2), motor.value is not None and motor.value > 0)[1])
    motor.safe_stop()
    command.publish(0.3)
    time.sleep(0.05)
    assert motor.mode == "safe" and motor.value == 0.0
    assert float(node.backends["motor"].read()) == 0.0  # type: ignore[arg-type]


def test_controllers_can_be_added_and_removed_at_run_time(
    nodes: Callable[[System, str], NodeRuntime], transport: Transport, tmp_path: Path
) -> None:
    path = tmp_path / "switching.xml"
    path.write_text(SWITCHING)
    system = ckmconf.load(path)
    node = nodes(system, "n")
    reference = transport.publisher(node.topic("r"))
    outputs: list[Sample] = []
    transport.subscribe(node.topic("u"), outputs.append)
    assert until(lambda: (reference.publish(1.0), len(outputs) > 30)[1])
    template = system.nodes[0].controllers[1]  # "b", inactive in the file
    added = node.add_controller(dataclasses.replace(template, name="c", active=True))
    count = len(outputs)
    assert until(lambda: (reference.publish(1.0), len(outputs) > count + 20)[1])
    assert added.active and not node.controllers["a"].active
    jump = abs(outputs[count].value - outputs[count - 1].value)
    assert jump < 0.5  # taken over from the current output
    node.remove_controller("c")
    assert "c" not in node.controllers and "n.c" not in node.scheduler.tasks
    assert "controller-removed" in [e["kind"] for e in node.events]


def test_a_node_runs_the_smart_resources_it_hosts(
    nodes: Callable[[System, str], NodeRuntime], transport: Transport
) -> None:
    from ckm_lab.scenes import render_rgb_scene

    runtime = nodes(example("smart_resource_tcm.xml"), "camera-node")
    assert set(runtime.resources) == {"RGBD"}
    objects = transport.subscribe(runtime.topic("/rgbd/objects"))
    camera = transport.publisher(runtime.topic("/camera/image"))
    image = render_rgb_scene(["box_cereal"], seed=3).image
    found: list[Any] = []

    def recognized() -> bool:
        camera.publish({"width": 640, "height": 480, "encoding": "rgb8", "data": image.tobytes()})
        sample = objects.latest()
        if sample is not None:
            found[:] = [o["name"] for o in sample.value["objects"]]
        return "box_cereal" in found

    assert until(recognized)
    stats = runtime.statistics()["resources"]["RGBD"]
    assert stats["streams"]["grab"]["frames"] > 0 and stats["instances"]["RGB-recog"]["published"] > 0
