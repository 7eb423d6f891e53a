"""The editor's window on the use case while a run goes (issue K.5): agents' heartbeats and the
simulation's topics arrive over a private loopback network; the Monitor tab's map follows the robot
and the mission canvas highlights the agent's active state at the level it shows, nested or not."""

from __future__ import annotations

import re
import shutil
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from PySide6.QtCore import QSettings
from PySide6.QtGui import QImage
from PySide6.QtWidgets import QMessageBox
from pytestqt.qtbot import QtBot

from editor.app import MainWindow, main
from editor.views.sim_map import ESTIMATE, to_scene
from runtime.network import Publisher, TopicQoS, Transport, open_transport
from runtime.resources import codec
from tests.editor.test_live import _network_xml, cell
from tests.runtime.network.conftest import private_network

LAB = Path(__file__).resolve().parents[2] / "configs" / "usecase" / "lab.xml"
BEAT = "ckm/agent-heartbeat"


def until(qtbot: QtBot, send: Callable[[], None], done: Callable[[], bool], what: str, timeout: float = 20.0) -> None:
    """Keep sending (heartbeats and streams are periodic) until ``done``, at most ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        send()
        qtbot.wait(150)
        if done():
            return
    raise AssertionError(f"{what} not seen within {timeout:g} s")


def test_the_window_follows_a_run_on_the_map_and_the_mission_canvas(qtbot: QtBot, tmp_path: Path) -> None:
    network = private_network()
    sim: Transport = open_transport(network, name="sim")
    sim.setup()
    sim.start()
    settings = QSettings(str(tmp_path / "editor.ini"), QSettings.Format.IniFormat)
    win = MainWindow(LAB, settings=settings, ask=lambda *_: QMessageBox.StandardButton.Discard)
    qtbot.addWidget(win)
    win._transport = open_transport(network, name="ckm-editor")  # the private network, not the lab's
    win._transport.setup()
    win._transport.start()
    try:
        win.tabs.setCurrentWidget(win.monitor)  # joins and subscribes
        beats: Publisher = sim.publisher(TopicQoS("/plan/individual/agents", BEAT, history=8))
        pose = sim.publisher(TopicQoS("/sim/turtlebot/pose", "Pose2D"))
        assert sim.wait_for_subscribers("/plan/individual/agents", 1, timeout=20.0)
        assert sim.wait_for_subscribers("/sim/turtlebot/pose", 1, timeout=20.0)
        state = {"agent": "turtlebot", "state": "Agent1Fetch/Navigation/NAV", "t": 1.0, "progress": 0.2}
        other: dict[str, Any] = {"agent": "nao", "state": "Agent2Spot/TRACK", "t": 1.0, "progress": 0.1}

        def send() -> None:
            beats.publish(state)
            beats.publish(other)  # another agent's mission: never highlighted on this canvas
            pose.publish(codec.encode({"x": 3.0, "y": 2.0, "yaw": 0.0}))

        win.open_mission("Agent1Fetch")  # the top mission: its state Navigation runs the nested NAV
        until(qtbot, send, lambda: win.canvas.active == "Navigation", "Navigation highlighted on Agent1Fetch")
        truth = win.monitor.live.map.robots["turtlebot"]["truth"]
        until(qtbot, send, truth.isVisible, "the Turtlebot's true pose on the map")
        assert truth.pos() == to_scene(3.0, 2.0)
        win.open_mission("Navigation")  # the nested mission: its own state
        until(qtbot, send, lambda: win.canvas.active == "NAV", "NAV highlighted on Navigation")
        state["state"] = "Agent1Fetch/ObjectInteraction/SPOT"
        win.open_mission("Agent1Fetch")
        until(qtbot, send, lambda: win.canvas.active == "ObjectInteraction", "the next state highlighted")
        rows = {cell(win.monitor.agents_table, r, 0) for r in range(win.monitor.agents_table.rowCount())}
        assert rows == {"turtlebot", "nao"}
    finally:
        win.close()
        sim.stop()


def test_a_monitor_screenshot_shows_the_running_simulation(tmp_path: Path) -> None:
    network = private_network()
    lab = tmp_path / "usecase"
    shutil.copytree(LAB.parent, lab)
    part = lab / "network.xml"
    part.write_text(re.sub(r"<Network\b[^>]*/>", _network_xml(network), part.read_text(), count=1, flags=re.S))
    sim = open_transport(network, name="sim")
    sim.setup()
    sim.start()
    stop = threading.Event()
    estimate = sim.publisher(TopicQoS("/nav/pose", "PoseEstimate"))

    def publish() -> None:  # the estimate, every 50 ms while the editor listens
        message = {"pose": {"x": 5.0, "y": 3.5, "yaw": 0.0}, "covariance": [0.04, 0, 0, 0, 0.04, 0, 0, 0, 0.01]}
        while not stop.wait(0.05):
            estimate.publish(codec.encode(message))

    worker = threading.Thread(target=publish, daemon=True)
    worker.start()
    try:
        target = tmp_path / "monitor.png"
        assert main([str(lab / "lab.xml"), "--screenshot", str(target), "--view", "monitor"]) == 0
    finally:
        stop.set()
        worker.join(timeout=5)
        sim.stop()
    image = QImage(str(target)).convertToFormat(QImage.Format.Format_RGB888)
    rows = np.frombuffer(image.constBits(), dtype=np.uint8).reshape(image.height(), image.bytesPerLine())
    pixels = rows[:, : image.width() * 3].reshape(image.height(), image.width(), 3).astype(int)
    blue = np.array([ESTIMATE.red(), ESTIMATE.green(), ESTIMATE.blue()])
    near = int(np.all(np.abs(pixels - blue) <= 12, axis=2).sum())
    assert near >= 10, f"the estimate's outline is not in the screenshot ({near} pixels of its colour)"
