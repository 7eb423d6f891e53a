"""The ROS bridge view of the Monitor tab: ROS 2 topics seen on the Zenoh side, with their types (issue L point 4).

ROS 2 nodes running rmw_zenoh announce every publisher, subscription, service and client with a
liveliness token (:mod:`runtime.network.rmw_graph`). This view follows those tokens on a Zenoh
network and lists, per topic or service, its ROS type, how many publishers and subscribers (servers
and clients) are alive, and their nodes: what a ROS 2 user sees with ``ros2 topic list -t`` next to
the CKM topics of the Monitor.

The view watches a Zenoh session it is given (:meth:`RosBridgePanel.start`), or opens its own from a
``<Network>`` (:meth:`RosBridgePanel.open`): the system's Zenoh network, or by default a client of
the ROS side's router ``rmw_zenohd`` at ``tcp/localhost:7447``. It imports only ckmconf,
``runtime.network`` and Zenoh (the editor-protocols contract).
"""

from __future__ import annotations

from typing import Any

import zenoh
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QLabel, QTableWidget, QTableWidgetItem, QVBoxLayout, QWidget

from ckmconf.model import Connect, Network, Zenoh
from runtime.network.rmw_graph import GraphTopic, RosGraph
from runtime.network.zenoh_session import zenoh_config

HEADERS = ["name", "type", "kind", "publishers / servers", "subscribers / clients", "nodes"]
ROUTER = "tcp/localhost:7447"
"""Where rmw_zenohd listens by default."""


def ros_router_network(endpoint: str = ROUTER) -> Network:
    """A Zenoh client of the ROS side's router, without multicast scouting (rmw_zenoh's own setting)."""
    return Network(
        transport="zenoh", zenoh=Zenoh(mode="client", multicast_scouting=False, connect=(Connect(endpoint=endpoint),))
    )


def row_of(topic: GraphTopic) -> list[str]:
    """One table row: a topic shows publishers and subscribers, a service its servers and clients."""
    service = topic.services + topic.clients > 0 and topic.publishers + topic.subscriptions == 0
    first, second = (topic.services, topic.clients) if service else (topic.publishers, topic.subscriptions)
    name = topic.name if topic.domain_id == 0 else f"{topic.name} (domain {topic.domain_id})"
    return [name, topic.type_name, "service" if service else "topic", str(first), str(second), ", ".join(topic.nodes)]


class RosBridgePanel(QWidget):
    """The ROS topics seen on a Zenoh network (see the module docstring).

    Args:
        domain_id: only this ROS domain (every domain by default).
    """

    def __init__(self, parent: QWidget | None = None, *, domain_id: int | None = None) -> None:
        super().__init__(parent)
        self.graph = RosGraph(domain_id)
        self.status = QLabel("ROS 2 (rmw_zenoh): not watching")
        self.table = QTableWidget(0, len(HEADERS))
        self.table.setHorizontalHeaderLabels(HEADERS)
        self.table.horizontalHeader().setStretchLastSection(True)
        self.table.verticalHeader().setVisible(False)
        layout = QVBoxLayout(self)
        layout.addWidget(self.status)
        layout.addWidget(self.table)
        self._session: zenoh.Session | None = None  # opened here: closed at stop()
        self._watch: Any = None
        self.timer = QTimer(self)
        self.timer.timeout.connect(self.refresh)

    def start(self, session: zenoh.Session) -> None:
        """Watch the liveliness tokens of ``session``'s network; the table refreshes every 0.5 s."""
        self.stop()
        self._watch = self.graph.watch(session)
        self.status.setText(f"ROS 2 (rmw_zenoh): watching session {session.zid()}")
        self.timer.start(500)

    def open(self, network: Network | None = None) -> None:
        """Open a Zenoh session of ``network`` (default: a client of rmw_zenohd) and watch it.

        Raises:
            zenoh.ZError: the session cannot be opened (a client whose router does not answer).
        """
        session = zenoh.open(zenoh_config(network or ros_router_network()))
        self.start(session)
        self._session = session

    def stop(self) -> None:
        """Stop watching; close the session :meth:`open` made (the caller's own stays open)."""
        self.timer.stop()
        watch, self._watch = self._watch, None
        if watch is not None:
            watch.undeclare()
        session, self._session = self._session, None
        if session is not None:
            session.close()  # type: ignore[no-untyped-call]

    def rows(self) -> list[list[str]]:
        """The table's rows now, from the tokens alive."""
        return [row_of(topic) for topic in self.graph.topics()]

    def refresh(self) -> None:
        """Redraw the table from the tokens alive."""
        rows = self.rows()
        self.table.setRowCount(len(rows))
        for r, row in enumerate(rows):
            for c, text in enumerate(row):
                self.table.setItem(r, c, QTableWidgetItem(text))
        if self._watch is not None:
            self.status.setText(f"ROS 2 (rmw_zenoh): {len(rows)} topic(s) and service(s) seen")

    def closeEvent(self, event: Any) -> None:
        """Stop watching the network, then close."""
        self.stop()
        super().closeEvent(event)
