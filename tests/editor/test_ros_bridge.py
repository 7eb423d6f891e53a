"""The Monitor's ROS bridge view (issue L point 4): ROS 2 topics seen on the Zenoh side, with their types.

A Zenoh session stands for a ROS 2 node running rmw_zenoh: it declares the liveliness tokens that
node would (written with runtime.ros.rmw_zenoh, checked there against rmw_zenoh's design document)
on a private Zenoh network on 127.0.0.1; the view, offscreen, opens its own session on that network
and lists what it sees, and forgets an endpoint whose token goes.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh
from pytestqt.qtbot import QtBot

import ckmconf
from ckmconf.model import Network, System
from editor.views.live import MonitorPanel, open_network
from editor.views.ros_bridge import HEADERS, RosBridgePanel
from runtime.network import Transport
from runtime.network.rmw_graph import GraphEndpoint, parse_endpoint
from runtime.network.zenoh_session import zenoh_config
from runtime.ros.bridge import RmwZenohBridge
from runtime.ros.rmw_zenoh import Endpoint, EntityKind, RmwQos, liveliness_token, parse_liveliness_token
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network, transports  # noqa: F401 (fixture)

HASH = "RIHS01_" + "ab" * 32
ZID = "1234abcd"


def token(kind: EntityKind, entity: int, topic: str, type_name: str, *, node: str = "talker", ns: str = "") -> str:
    return liveliness_token(
        0, ZID, 3, entity, kind, node, namespace=ns, endpoint=Endpoint(topic, type_name, HASH, RmwQos(depth=7))
    )


@pytest.mark.parametrize(
    ("kind", "topic", "type_name", "ns"),
    [
        (EntityKind.PUBLISHER, "/chatter", "std_msgs/msg/String", ""),
        (EntityKind.SUBSCRIPTION, "/robot1/scan", "sensor_msgs/msg/LaserScan", "/robot1"),
        (EntityKind.SERVICE, "/add_two_ints", "example_interfaces/srv/AddTwoInts", "/a/b"),
        (EntityKind.CLIENT, "/add_two_ints", "example_interfaces/srv/AddTwoInts", ""),
    ],
)
def test_the_graph_reads_tokens_as_rmw_zenoh_writes_them(kind: EntityKind, topic: str, type_name: str, ns: str) -> None:
    keyexpr = token(kind, 11, topic, type_name, ns=ns)
    full = parse_liveliness_token(keyexpr)
    assert full.endpoint is not None
    expected_node = f"{ns.rstrip('/')}/talker" if ns else "/talker"
    assert parse_endpoint(keyexpr) == GraphEndpoint(
        full.domain_id, full.endpoint.topic, full.endpoint.type_name, kind.name.lower(), expected_node
    )


def test_node_tokens_and_other_keys_are_no_endpoints() -> None:
    assert parse_endpoint(liveliness_token(0, ZID, 3, 3, EntityKind.NODE, "talker")) is None
    assert parse_endpoint("ckm/@peer/12") is None
    assert parse_endpoint("@ros2_lv/0/z/1/2/MP/%/%/n/%chatter/not_a_dds_type/h/q") is None


def cell(panel: RosBridgePanel, row: int, column: int) -> str:
    item = panel.table.item(row, column)
    assert item is not None
    return item.text()


@pytest.fixture
def ros_node() -> Iterator[tuple[zenoh.Session, Network]]:
    """A Zenoh session on a private network, standing for a ROS 2 node, and that network."""
    network = private_network("zenoh")
    session = zenoh.open(zenoh_config(network))
    yield session, network
    session.close()  # type: ignore[no-untyped-call]


@pytest.mark.timeout(60)
def test_the_view_lists_ros_topics_seen_on_zenoh(qtbot: QtBot, ros_node: tuple[zenoh.Session, Network]) -> None:
    session, network = ros_node
    liveliness = session.liveliness()
    tokens = [
        liveliness.declare_token(liveliness_token(0, ZID, 3, 3, EntityKind.NODE, "talker")),
        liveliness.declare_token(token(EntityKind.PUBLISHER, 10, "/chatter", "std_msgs/msg/String")),
        liveliness.declare_token(
            token(EntityKind.SUBSCRIPTION, 11, "/robot1/scan", "sensor_msgs/msg/LaserScan", node="nav", ns="/robot1")
        ),
        liveliness.declare_token(token(EntityKind.SUBSCRIPTION, 12, "/chatter", "std_msgs/msg/String", node="nav")),
        liveliness.declare_token(token(EntityKind.SERVICE, 13, "/add", "example_interfaces/srv/AddTwoInts")),
    ]
    panel = RosBridgePanel()
    qtbot.addWidget(panel)
    panel.open(network)
    try:
        qtbot.waitUntil(lambda: len(panel.rows()) == 3, timeout=30_000)
        panel.refresh()
        table = [[cell(panel, r, c) for c in range(len(HEADERS))] for r in range(panel.table.rowCount())]
        assert table == [
            ["/add", "example_interfaces/srv/AddTwoInts", "service", "1", "0", "/talker"],
            ["/chatter", "std_msgs/msg/String", "topic", "1", "1", "/nav, /talker"],
            ["/robot1/scan", "sensor_msgs/msg/LaserScan", "topic", "0", "1", "/robot1/nav"],
        ]
        assert panel.status.text() == "ROS 2 (rmw_zenoh): 3 topic(s) and service(s) seen"
        tokens[1].undeclare()  # type: ignore[no-untyped-call]  # the talker's publisher goes
        qtbot.waitUntil(lambda: panel.rows()[1][3] == "0", timeout=30_000)
        assert panel.rows()[1] == ["/chatter", "std_msgs/msg/String", "topic", "0", "1", "/nav"]
    finally:
        panel.stop()
        for declared in tokens[2:]:
            declared.undeclare()  # type: ignore[no-untyped-call]


@pytest.mark.timeout(60)
def test_the_view_shows_what_the_ckm_bridge_offers(
    qtbot: QtBot,
    ros_node: tuple[zenoh.Session, Network],
    transports: Callable[..., Transport],  # noqa: F811
) -> None:
    session, network = ros_node  # here the bridge's session, on the Zenoh network the view opens
    system = ckmconf.load(REPO / "tests" / "data" / "ros" / "ros_typed_loop.xml")
    bridge = RmwZenohBridge(system, transports(private_network("multipeer"), "ckm"))
    bridge.start(session)
    panel = RosBridgePanel()
    qtbot.addWidget(panel)
    panel.open(network)
    try:
        qtbot.waitUntil(lambda: len(panel.rows()) == 2, timeout=30_000)
        assert panel.rows() == [
            ["/reading", "ckm_test_msgs/msg/Reading", "topic", "1", "1", "/ckm_bridge"],
            ["/scan", "sensor_msgs/msg/LaserScan", "topic", "1", "1", "/ckm_bridge"],
        ]
    finally:
        panel.stop()
        bridge.stop()


@pytest.mark.timeout(60)
def test_the_monitor_tab_watches_the_ros_side_of_a_zenoh_system(
    qtbot: QtBot, ros_node: tuple[zenoh.Session, Network]
) -> None:
    session, network = ros_node
    token_ = session.liveliness().declare_token(token(EntityKind.PUBLISHER, 20, "/odom", "nav_msgs/msg/Odometry"))
    system = System(name="zenoh-system", version="1.0", network=network)
    monitor = MonitorPanel(lambda: open_network(system, Path.cwd(), network))
    qtbot.addWidget(monitor)
    try:
        monitor.start(system)
        qtbot.waitUntil(lambda: any(row[0] == "/odom" for row in monitor.ros.rows()), timeout=30_000)
    finally:
        monitor.timer.stop()
        monitor.ros.stop()
        token_.undeclare()  # type: ignore[no-untyped-call]


def test_a_multipeer_system_opens_no_ros_session(qtbot: QtBot) -> None:
    system = System(name="multipeer-system", version="1.0", network=private_network("multipeer"))
    monitor = MonitorPanel(lambda: open_network(system, Path.cwd(), system.network))
    qtbot.addWidget(monitor)
    try:
        monitor.start(system)
        assert monitor.ros.status.text() == "ROS 2 (rmw_zenoh): not watching"
    finally:
        monitor.timer.stop()
