"""The parts of a node (issue H point 3): alarm reactions through ReactionHost, switching's one
staleness rule, and a Smart Resource stream its records cannot make refused at its service."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

import ckmconf
from ckmconf.errors import ConfigError
from ckmconf.model import Alarm
from ckmconf.model.resources import (
    Plugin,
    Profile,
    Scenario,
    Service,
    ServiceInput,
    ServiceOutput,
    SmartResource,
    Use,
)
from runtime.kernel.node import NodeRuntime
from runtime.kernel.reactions import react
from runtime.kernel.services import stale_after
from runtime.network import TopicQoS, Transport, open_transport
from runtime.resources.resource import SmartResourceRuntime
from tests.conftest import REPO
from tests.runtime.kernel.test_node import SWITCHING
from tests.runtime.network.conftest import private_network
from tests.runtime.resources.plugin_host_peer import registry
from tests.waiting import until


@pytest.fixture
def transport() -> Iterator[Transport]:
    running = open_transport(private_network(), name="parts-test")
    running.setup()
    running.start()
    yield running
    running.stop()


@pytest.fixture
def node(transport: Transport, tmp_path: Path) -> Iterator[NodeRuntime]:
    path = tmp_path / "switching.xml"
    path.write_text(SWITCHING)
    system = ckmconf.load(path)
    runtime = NodeRuntime(system.nodes[0], system, transport)
    runtime.setup()  # built, not started: the reactions act on the built services
    yield runtime
    runtime.stop()


def test_a_switch_alarm_hands_the_outputs_over_and_is_logged(node: NodeRuntime) -> None:
    assert node.controllers["a"].active and not node.controllers["b"].active
    react(node, Alarm(name="hot", measure="cpu", above=0.9, action="switch", target="b"))
    assert node.controllers["b"].active and not node.controllers["a"].active
    assert node.events[-1]["kind"] == "controller-switched" and node.events[-1]["reason"] == "alarm hot"


def test_a_reaction_the_node_cannot_carry_out_is_reported(node: NodeRuntime) -> None:
    react(node, Alarm(name="crash", measure="partition-crash", action="restart"))  # no partition supervisor
    assert node.events[-1]["kind"] == "reaction-unavailable" and node.events[-1]["alarm"] == "crash"


def test_a_safe_stop_alarm_drives_every_actuator_to_its_safe_value(node: NodeRuntime) -> None:
    react(node, Alarm(name="over", measure="cpu", above=0.9, action="safe-stop"))
    assert all(a.mode == "safe" and a.value == 0.0 for a in node.actuators.values())


def test_one_staleness_rule_the_lifespan_else_three_periods() -> None:
    assert stale_after(TopicQoS("/a", lifespan=0.2), 0.01) == 0.2
    assert stale_after(TopicQoS("/a"), 0.02) == pytest.approx(0.06)
    # A deadline is the publisher's promised rate (watched by the monitor), not an age limit (D141).
    assert stale_after(TopicQoS("/a", deadline=0.01), 0.02) == pytest.approx(0.06)


def test_a_stream_its_records_cannot_make_is_a_config_error_at_the_service(transport: Transport) -> None:
    resource = SmartResource(
        name="cam",
        node="n",
        plugins=(Plugin(name="small", kind="resize"), Plugin(name="big", kind="resize")),
        profiles=(
            Profile(name="low", output="small", root=Use(plugin="small")),
            Profile(name="high", output="big", root=Use(plugin="big")),
        ),
        services=(
            Service(
                name="Images",
                inputs=(ServiceInput(name="image", topic="/cam/raw"),),
                outputs=(ServiceOutput(name="image", topic="/cam/out"),),
                scenarios=(Scenario(name="LOW", profile="low"), Scenario(name="HIGH", profile="high")),
            ),
        ),
    )
    runtime = SmartResourceRuntime(resource, transport, registry=registry())
    with pytest.raises(ConfigError) as refused:
        runtime.setup()
    assert refused.value.xpath == "/Service" and "must share one acquisition plugin" in refused.value.message


@pytest.mark.parametrize("stopping", [False, True])
def test_a_node_being_stopped_no_longer_judges_its_alarms(transport: Transport, tmp_path: Path, stopping: bool) -> None:
    """Host.stop calls stop_monitoring before it ends the partitions: a topic that goes (or stays)
    unpublished while the run stops is not the run's fault (a 3 s lab run failed on scan_stale so)."""
    text = (REPO / "tests" / "data" / "run" / "serious_alarm.xml").read_text()
    path = tmp_path / "alarm.xml"
    path.write_text(text.replace('above="0.2" severity="error"', 'above="0.2" hold="0.5" severity="error"'))
    system = ckmconf.load(path)
    runtime = NodeRuntime(system.nodes[0], system, transport)
    runtime.setup()
    runtime.start()
    try:
        if stopping:
            runtime.stop_monitoring()
        assert runtime.monitor is not None
        state = runtime.monitor.alarms["heartbeat_lost"]
        raised = until(lambda: state.raised > 0, 2.0)
        assert raised is not stopping
    finally:
        runtime.stop()
