"""Live views: distribution to node agents (§3.1.5.2) and monitoring of a running system.

Both talk to the network of the edited system (its ``<Network>``, group key included) through one
transport the window opens on demand. Network callbacks run on the transport's threads, so they
only fill thread-safe directories and counters; a Qt timer redraws from them twice a second.

Agents: the ``ckm-run --await-config`` agents heard on ``/ckm/agents`` with their status, node and
configuration hash; each node of the system is mapped to an agent (by default the agent of the
same name), and **Distribute** pushes every node its bundle (D58) and shows each answer — the hash
confirmed, or the errors the agent refused it with.

Monitor: every topic of the system on the network (its own and its nodes' external ones) with its
rate, every service announced on ``/ckm/services`` with its active scenario, measures and last
alarm, and each plan agent's active state — which the mission canvas highlights when it shows that
mission; beside them, for a simulation, the live map and camera images of editor/views/sim_map.py.
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import (
    QComboBox,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSplitter,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from ckmconf.model import Network, System
from runtime.network import Sample, TopicQoS, Transport, open_transport, read_group_key
from runtime.resources.api import DIRECTORY_TOPIC

from ..distribution import Ack, AgentDirectory, distribute
from .ros_bridge import RosBridgePanel
from .sim_map import SimLivePanel


def open_network(system: System | None, base: Path, network: Network | None = None) -> Transport:
    """A started transport on the system's network (or ``network``), with its group key."""
    chosen = network or (system.network if system is not None and system.network else Network())
    transport = open_transport(chosen, name="ckm-editor", key=read_group_key(chosen, base))
    transport.setup()
    transport.start()
    return transport


def _table(headers: list[str]) -> QTableWidget:
    table = QTableWidget(0, len(headers))
    table.setHorizontalHeaderLabels(headers)
    table.horizontalHeader().setStretchLastSection(True)
    table.verticalHeader().setVisible(False)
    return table


def _fill(table: QTableWidget, rows: list[list[str]]) -> None:
    table.setRowCount(len(rows))
    for r, row in enumerate(rows):
        for c, text in enumerate(row):
            table.setItem(r, c, QTableWidgetItem(text))


class AgentsPanel(QWidget):
    """Discovered agents, the node → agent mapping, and distribution (see the module docstring)."""

    def __init__(self, transport: Callable[[], Transport], parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._transport = transport
        self.directory: AgentDirectory | None = None
        self.system: System | None = None
        self.main: Path | None = None
        self.results: dict[str, Ack] = {}
        self.table = _table(["agent", "status", "node", "config", "host", "heard"])
        self.mapping = QFormLayout()
        self.button = QPushButton("Distribute")
        self.button.clicked.connect(self.distribute)
        self.outcome = QLabel()
        self.outcome.setWordWrap(True)
        layout = QVBoxLayout(self)
        layout.addWidget(QLabel("Node agents on the network (ckm-run --await-config):"))
        layout.addWidget(self.table)
        layout.addLayout(self.mapping)
        row = QHBoxLayout()
        row.addWidget(self.button)
        row.addStretch(1)
        layout.addLayout(row)
        layout.addWidget(self.outcome)
        self.combos: dict[str, QComboBox] = {}
        self._busy = threading.Event()
        self.timer = QTimer(self)
        self.timer.timeout.connect(self.refresh)

    def start(self) -> None:
        """Start listening for agents and refreshing the table."""
        if self.directory is None:
            self.directory = AgentDirectory(self._transport())
        self.timer.start(500)

    def show_system(self, system: System | None, main: Path | None) -> None:
        """Take the system's nodes and rebuild the node → agent mapping (each defaults to the agent of its name)."""
        self.system, self.main = system, main
        while self.mapping.rowCount():
            self.mapping.removeRow(0)
        self.combos = {}
        for node in system.nodes if system is not None else ():
            combo = QComboBox()
            combo.setEditable(True)
            combo.setCurrentText(node.name)
            self.mapping.addRow(QLabel(f"node {node.name} →"), combo)
            self.combos[node.name] = combo

    def refresh(self) -> None:
        """Redraw the agents table and the distribution answers."""
        agents = self.directory.agents() if self.directory is not None else []
        _fill(self.table, [
            [a.name, a.status + (" (silent)" if a.stale() else ""), a.node or "", (a.config_hash or "")[:12],
             str(a.announcement.get("host", "")), f"{a.age:.1f} s ago"]
            for a in agents
        ])  # fmt: skip
        names = [a.name for a in agents]
        for combo in self.combos.values():
            current = combo.currentText()
            if [combo.itemText(i) for i in range(combo.count())] != names:
                combo.clear()
                combo.addItems(names)
                combo.setCurrentText(current)
        if self.results and not self._busy.is_set():
            lines = []
            for node, ack in sorted(self.results.items()):
                if ack.confirmed:
                    lines.append(f"✔ {node} on {ack.agent}: running, hash {ack.hash[:12] if ack.hash else ''}")
                else:
                    reason = "; ".join(ack.errors) or "no answer"
                    lines.append(f"✖ {node} on {ack.agent}: refused — {reason}")
            self.outcome.setText("\n".join(lines))
            self.button.setEnabled(True)

    def mapping_now(self) -> dict[str, str]:
        """The agent chosen for each node, by node name (nodes without one left out)."""
        return {node: combo.currentText() for node, combo in self.combos.items() if combo.currentText()}

    def distribute(self, timeout: float = 15.0) -> None:
        """Push in a worker thread; the answers appear at the next refresh."""
        if self.main is None or self._busy.is_set():
            return
        self._busy.set()
        self.button.setEnabled(False)
        self.outcome.setText("Distributing…")
        transport, main, mapping = self._transport(), self.main, self.mapping_now()

        def work() -> None:
            try:
                self.results = distribute(transport, main, mapping, timeout)
            except (OSError, ValueError) as exc:
                self.results = {"*": Ack("?", "*", "", False, "", (str(exc),), True)}
            finally:
                self._busy.clear()

        threading.Thread(target=work, name="distribute", daemon=True).start()


class MonitorPanel(QWidget):
    """Topic rates, service qualities and agents' states of a running system."""

    def __init__(self, transport: Callable[[], Transport], parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._transport = transport
        self.system: System | None = None
        self.topics_table = _table(["topic", "messages/s", "total"])
        self.services_table = _table(["service", "scenario", "measures", "alarm"])
        self.agents_table = _table(["agent", "active state", "mission progress"])
        tables = QWidget()
        layout = QVBoxLayout(tables)
        for title, table in (("Topics", self.topics_table), ("Services", self.services_table),
                             ("Mission states", self.agents_table)):  # fmt: skip
            layout.addWidget(QLabel(title))
            layout.addWidget(table)
        self.ros = RosBridgePanel()  # ROS 2 topics seen through rmw_zenoh liveliness tokens (issue L)
        layout.addWidget(QLabel("ROS 2 bridge"))
        layout.addWidget(self.ros)
        self.live = SimLivePanel()  # the map, the robots, the recognised objects and the cameras
        split = QSplitter()
        split.addWidget(tables)
        split.addWidget(self.live)
        split.setSizes([450, 750])
        QVBoxLayout(self).addWidget(split)
        self._lock = threading.Lock()
        self.arrivals: dict[str, collections.deque[float]] = {}
        self.totals: dict[str, int] = collections.Counter()
        self.services: dict[str, dict[str, Any]] = {}
        self.states: dict[str, str | None] = {}
        self.progress: dict[str, float] = {}
        self.on_state: Callable[[str, str | None], None] | None = None
        self._subscribed: set[str] = set()
        self.timer = QTimer(self)
        self.timer.timeout.connect(self.refresh)

    def start(self, system: System | None) -> None:
        """Subscribe to the service directory, the system's topics and its plans' agent heartbeats."""
        self.system = system
        transport = self._transport()
        self._subscribe(transport, TopicQoS(DIRECTORY_TOPIC, "ckm/service", history=64), self._on_service)
        nodes = system.nodes if system is not None else ()
        external = [t for n in nodes for t in n.topics if t.scope == "external"]  # the nodes' topics on the network
        for topic in [*system.topics, *external] if system is not None else ():
            self._subscribe(transport, TopicQoS(topic.name, topic.type), self._count(topic.name))
        for plan in system.plans if system is not None else ():
            qos = TopicQoS(f"/plan/{plan.name}/agents", "ckm/agent-heartbeat", history=8)
            self._subscribe(transport, qos, self._on_beat)
        self.live.start(system, transport)
        network = system.network if system is not None else None
        if network is not None and network.transport == "zenoh":  # a multipeer system has no ROS side to see
            try:
                self.ros.open(network)
            except Exception as exc:  # zenoh.ZError: the session could not be opened; the rest still monitors
                self.ros.status.setText(f"ROS 2 (rmw_zenoh): not watching ({exc})")
        self.timer.start(500)

    def _subscribe(self, transport: Transport, qos: TopicQoS, callback: Callable[[Sample], None]) -> None:
        if qos.name not in self._subscribed:
            self._subscribed.add(qos.name)
            transport.subscribe(qos, callback)

    def _count(self, topic: str) -> Callable[[Sample], None]:
        def arrived(_: Sample) -> None:
            with self._lock:
                self.arrivals.setdefault(topic, collections.deque(maxlen=200)).append(time.monotonic())
                self.totals[topic] += 1

        return arrived

    def _on_service(self, sample: Sample) -> None:
        entry = sample.value
        if not isinstance(entry, dict) or entry.get("type") != "service":
            return
        key = f"{entry.get('resource')}.{entry.get('service')}"
        with self._lock:
            if key in self.services:
                return
            self.services[key] = {"scenario": "", "measures": {}, "alarm": ""}
        transport = self._transport()
        for topic in (entry.get("quality"), entry.get("alarms")):
            if isinstance(topic, str):
                self._subscribe(transport, TopicQoS(topic, "ckm/service-quality", history=16), self._quality(key))

    def _quality(self, key: str) -> Callable[[Sample], None]:
        def heard(sample: Sample) -> None:
            message = sample.value
            if not isinstance(message, dict) or message.get("client") != "":
                return
            with self._lock:
                record = self.services[key]
                if message.get("type") == "quality":
                    record["scenario"] = message.get("scenario") or ""
                    record["measures"] = message.get("measures") or {}
                elif message.get("type") == "alarm":
                    record["alarm"] = "raised" if message.get("raised") else "cleared"

        return heard

    def _on_beat(self, sample: Sample) -> None:
        beat = sample.value
        if isinstance(beat, dict) and isinstance(beat.get("agent"), str):
            with self._lock:
                self.states[beat["agent"]] = beat.get("state")
                if isinstance(beat.get("progress"), int | float):
                    self.progress[beat["agent"]] = float(beat["progress"])

    def refresh(self) -> None:
        """Redraw topic rates and totals, services and plan agents."""
        now = time.monotonic()
        with self._lock:
            rates = {t: sum(1 for a in q if now - a <= 2.0) / 2.0 for t, q in self.arrivals.items()}
            topics = [[t, f"{rates.get(t, 0.0):.1f}", str(self.totals[t])] for t in sorted(self.totals)]
            services = [
                [k, v["scenario"], ", ".join(f"{m} {x:.3g}" for m, x in sorted(v["measures"].items())), v["alarm"]]
                for k, v in sorted(self.services.items())
            ]
            states = dict(self.states)
            progress = dict(self.progress)
        _fill(self.topics_table, topics)
        _fill(self.services_table, services)
        _fill(self.agents_table, [[a, s or "—", f"{progress.get(a, 0.0):.0%}"] for a, s in sorted(states.items())])
        self.live.refresh()
        if self.on_state is not None:
            for agent, state in states.items():
                self.on_state(agent, state)
