"""Distribution and monitoring from the editor's window: two ``ckm-run --await-config`` agents
on a private loopback network are discovered, the system is pushed to them from the Agents tab,
and the Monitor tab sees their topics."""

from __future__ import annotations

import shutil
from pathlib import Path

from PySide6.QtCore import QSettings
from PySide6.QtWidgets import QMessageBox, QTableWidget
from pytestqt.qtbot import QtBot

from ckmconf.model import Network
from editor.app import MainWindow
from tests.runtime.network.conftest import private_network
from tests.runtime.test_distribution import agent_processes, write_network

DATA = Path(__file__).resolve().parents[1] / "data" / "distribution"


def cell(table: QTableWidget, row: int, column: int) -> str:
    item = table.item(row, column)
    return "" if item is None else item.text()


def _network_xml(network: Network) -> str:
    return (
        f'<Network transport="multipeer" group="{network.group}" discoveryPort="{network.discovery_port}" '
        f'interface="127.0.0.1" basePort="{network.base_port}" portTries="{network.port_tries}" '
        f'heartbeat="{network.heartbeat}"/>'
    )


def test_distribute_from_the_agents_tab_and_monitor_the_result(qtbot: QtBot, tmp_path: Path) -> None:
    network = private_network()
    (tmp_path / "parts").mkdir()
    shutil.copy(DATA / "parts" / "topics.xml", tmp_path / "parts" / "topics.xml")
    text = (DATA / "two_nodes.xml").read_text()
    include = '<Include href="parts/topics.xml"/>'
    text = text.replace(include, include + "\n  " + _network_xml(network))  # Network follows the Includes
    system = tmp_path / "two_nodes.xml"
    system.write_text(text)
    agents_dir = tmp_path / "agents"
    agents_dir.mkdir()
    net = write_network(agents_dir, network)
    with agent_processes(net, agents_dir) as spawn:
        spawn("left")  # named after the nodes: the default mapping needs no change
        spawn("right")
        settings = QSettings(str(tmp_path / "editor.ini"), QSettings.Format.IniFormat)
        win = MainWindow(system, settings=settings, ask=lambda *_: QMessageBox.StandardButton.Discard)
        qtbot.addWidget(win)
        assert win.document.problems == []
        win.tabs.setCurrentWidget(win.agents)
        qtbot.waitUntil(lambda: win.agents.table.rowCount() == 2, timeout=30_000)
        assert win.agents.mapping_now() == {"left": "left", "right": "right"}
        win.agents.distribute()
        qtbot.waitUntil(lambda: win.agents.outcome.text().count("✔") == 2, timeout=30_000)
        assert "left on left: running" in win.agents.outcome.text()
        qtbot.waitUntil(lambda: {cell(win.agents.table, r, 1) for r in range(2)} == {"running"}, timeout=10_000)
        hashes = {cell(win.agents.table, r, 3) for r in range(2)}
        # A bad configuration is refused with its errors, and the agents keep the old one.
        sensor = next(win.document.main.root.iter("{urn:ckm:1}Sensor"))
        win.document.set_attribute(sensor, "period", "0")
        assert win.save()
        win.agents.results = {}
        win.agents.distribute()
        qtbot.waitUntil(lambda: win.agents.outcome.text().count("✖") == 2, timeout=30_000)
        assert "refused" in win.agents.outcome.text()
        assert {cell(win.agents.table, r, 3) for r in range(2)} == hashes
        assert {cell(win.agents.table, r, 1) for r in range(2)} == {"running"}
        win.tabs.setCurrentWidget(win.monitor)

        def rates() -> dict[str, float]:
            table = win.monitor.topics_table
            return {cell(table, r, 0): float(cell(table, r, 1) or 0) for r in range(table.rowCount())}

        qtbot.waitUntil(lambda: rates().get("/dist/left/speed", 0) > 10 and rates().get("/dist/right/speed", 0) > 10,
                        timeout=20_000)  # fmt: skip
        win.close()
