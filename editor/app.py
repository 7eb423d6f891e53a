"""ckm-editor [FILE] [--screenshot PNG [--view VIEW]]: the configuration editor's main window.

A system tree on the left, the selected element's form, its mission canvas, the topic graph and
the plan view in the middle, the problems at the bottom. Every edit is an undoable command;
File offers new, open, save, save as and recent files, and closing with unsaved changes asks.
With ``--screenshot`` the window is rendered offscreen to PNG and the program exits 0 (``--view``
picks what is shown: ``tree``, ``element:NAME``, ``mission:NAME``, ``topics``, ``plan``, or
``monitor``: the Monitor tab after listening to the system's network for ``MONITOR_WAIT`` seconds,
with the live map of a running simulation).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from PySide6.QtCore import QSettings, Qt
from PySide6.QtGui import QAction, QCloseEvent, QKeySequence
from PySide6.QtWidgets import (
    QApplication,
    QDockWidget,
    QFileDialog,
    QMainWindow,
    QMessageBox,
    QScrollArea,
    QTabWidget,
    QWidget,
)

from runtime.network import Transport

from .document import Element, local
from .model.schema import SchemaModel
from .views.form import AttributeForm
from .views.graphs import PlanView, TopicGraph
from .views.live import AgentsPanel, MonitorPanel, open_network
from .views.mission import MissionCanvas
from .views.problems import ProblemsPanel
from .views.tree import SystemTree
from .workspace import Workspace

MAX_RECENT = 8
MONITOR_WAIT = 3.0  # s a monitor screenshot listens before it is taken (the use case's poses come every 0.8 s)
Ask = Callable[[QWidget, str], QMessageBox.StandardButton]


def _ask_save(parent: QWidget, name: str) -> QMessageBox.StandardButton:
    buttons = QMessageBox.StandardButton.Save | QMessageBox.StandardButton.Discard | QMessageBox.StandardButton.Cancel
    return QMessageBox.question(parent, "Unsaved changes", f"Save the changes to {name}?", buttons)


class MainWindow(QMainWindow):
    """The editor (see the module docstring). ``settings`` and ``ask`` are injectable for tests."""

    def __init__(self, path: Path | None = None, *, settings: QSettings | None = None, ask: Ask = _ask_save) -> None:
        super().__init__()
        self.settings = settings if settings is not None else QSettings("CKM", "ckm-editor")
        self.ask = ask
        self._transport: Transport | None = None
        self.schema = SchemaModel.load()
        self.resize(1400, 860)
        self.document = Workspace(path, parent=self)
        self._build()
        self._menus()
        self._open_document(self.document)

    # ------------------------------------------------------------------ layout

    def _build(self) -> None:
        self.tabs = QTabWidget()
        self.setCentralWidget(self.tabs)
        self.tree_dock = QDockWidget("System", self)
        self.tree_dock.setObjectName("system")
        self.addDockWidget(Qt.DockWidgetArea.LeftDockWidgetArea, self.tree_dock)
        self.problems_dock = QDockWidget("Problems", self)
        self.problems_dock.setObjectName("problems")
        self.addDockWidget(Qt.DockWidgetArea.BottomDockWidgetArea, self.problems_dock)
        self.resizeDocks([self.tree_dock], [360], Qt.Orientation.Horizontal)
        self.resizeDocks([self.problems_dock], [150], Qt.Orientation.Vertical)

    def _open_document(self, document: Workspace) -> None:
        if document is not self.document:
            self.document.modified_changed.disconnect()
            self.document.deleteLater()
        self.document = document
        self.tree = SystemTree(document, self.schema)
        self.tree_dock.setWidget(self.tree)
        self.form = AttributeForm(document, self.schema)
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setWidget(self.form)
        self.canvas = MissionCanvas(document)
        self.topics = TopicGraph()
        self.plan = PlanView()
        self.tabs.clear()
        self.tabs.addTab(scroll, "Properties")
        self.tabs.addTab(self.canvas, "Mission")
        self.tabs.addTab(self.topics, "Topics")
        self.tabs.addTab(self.plan, "Plan")
        self.agents = AgentsPanel(self.network)
        self.monitor = MonitorPanel(self.network)
        self.monitor.on_state = self._live_state
        self.tabs.addTab(self.agents, "Agents")
        self.tabs.addTab(self.monitor, "Monitor")
        self.tabs.currentChanged.connect(self._tab_shown)
        self.problems = ProblemsPanel(document)
        self.problems_dock.setWidget(self.problems)
        self.tree.selected.connect(self._selected)
        self.canvas.selected.connect(self.tree.select)
        self.canvas.open_mission.connect(self.open_mission)
        self.problems.chosen.connect(self.tree.select)
        document.problems_changed.connect(self._refresh_graphs)
        document.modified_changed.connect(self._title)
        document.main.path_changed.connect(self._title)
        self.undo_action.setEnabled(True)
        self._rebind_undo()
        document.validate()
        self.tree.select(document.main.root)
        self._selected(document.main.root)
        self._title()

    def _rebind_undo(self) -> None:
        stack = self.document.undo
        self.undo_action.triggered.disconnect()
        self.redo_action.triggered.disconnect()
        self.undo_action.triggered.connect(stack.undo)
        self.redo_action.triggered.connect(stack.redo)

    def _menus(self) -> None:
        file = self.menuBar().addMenu("&File")
        for text, key, slot in (
            ("&New", QKeySequence.StandardKey.New, self.new),
            ("&Open…", QKeySequence.StandardKey.Open, self.open_dialog),
            ("&Save", QKeySequence.StandardKey.Save, self.save),
            ("Save &As…", QKeySequence.StandardKey.SaveAs, self.save_as_dialog),
        ):
            action = file.addAction(text)
            action.setShortcut(key)
            action.triggered.connect(slot)
        self.recent_menu = file.addMenu("Open &Recent")
        self._fill_recent()
        file.addSeparator()
        quit_action = file.addAction("&Quit")
        quit_action.setShortcut(QKeySequence.StandardKey.Quit)
        quit_action.triggered.connect(self.close)
        edit = self.menuBar().addMenu("&Edit")
        self.undo_action = QAction("&Undo", self)
        self.undo_action.setShortcut(QKeySequence.StandardKey.Undo)
        self.redo_action = QAction("&Redo", self)
        self.redo_action.setShortcut(QKeySequence.StandardKey.Redo)
        self.undo_action.triggered.connect(lambda: None)
        self.redo_action.triggered.connect(lambda: None)
        remove = QAction("&Remove element", self)
        remove.setShortcut(QKeySequence.StandardKey.Delete)
        remove.triggered.connect(lambda: self.tree.remove_current())
        for action in (self.undo_action, self.redo_action, remove):
            edit.addAction(action)

    def _title(self) -> None:
        name = self.document.main.path.name if self.document.main.path else "untitled"
        self.setWindowTitle(f"{name}{' *' if self.document.modified else ''} — CKM editor")

    # ------------------------------------------------------------------ selection

    def _selected(self, element: Element) -> None:
        self.form.show_element(element)
        mission: Element | None = element
        while mission is not None and local(mission) != "Mission":
            mission = mission.getparent()
        if mission is not None and mission is not self.canvas.mission:
            self.canvas.show_mission(mission)

    def open_mission(self, name: str) -> None:
        """Show mission ``name`` (ckm.xsd ``Mission``) on the canvas and select it in the tree."""
        element = self.document.mission(name)
        if element is not None:
            self.tree.select(element)
            self.canvas.show_mission(element)
            self.tabs.setCurrentWidget(self.canvas)

    def _refresh_graphs(self) -> None:
        self.topics.show_system(self.document.system)
        self.plan.show_system(self.document.system)
        self.agents.show_system(self.document.system, self.document.main.path)

    # ------------------------------------------------------------------ the live system

    def network(self) -> Transport:
        """The transport to the edited system's network, opened the first time it is needed."""
        if self._transport is None:
            base = self.document.main.path.parent if self.document.main.path else Path.cwd()
            self._transport = open_network(self.document.last_system, base)
        return self._transport

    def _tab_shown(self, index: int) -> None:
        widget = self.tabs.widget(index)
        try:
            if widget is self.agents:
                self.agents.start()
            elif widget is self.monitor:
                self.monitor.start(self.document.last_system)
        except (OSError, ValueError) as exc:  # no network, a bad group key file
            QMessageBox.warning(self, "Network", f"cannot join the system's network: {exc}")

    def _live_state(self, agent: str, path: str | None) -> None:
        """Highlight an agent's active state when the canvas shows its mission or one nested in it.

        ``path`` is ``TOP/STATE/…/STATE`` (runtime/missions/hfsm.py): each state but the last runs the
        mission its ``<State mission=…>`` names, so the canvas's mission is found along it and its
        state on the path is the one highlighted (the whole nested mission's box, at the top level).
        """
        shown = self.canvas.mission.get("name") if self.canvas.mission is not None else None
        parts = (path or "").split("/")
        mission: str | None = parts[0]
        for state in parts[1:]:
            if mission == shown:
                if state in self.canvas.nodes and self.canvas.active != state:
                    self.canvas.highlight(state)
                return
            element = self.document.mission(mission) if mission else None
            children = list(element) if element is not None else []
            states = [e for e in children if isinstance(e.tag, str) and local(e) == "State"]
            mission = next((e.get("mission") for e in states if e.get("name") == state), None)

    # ------------------------------------------------------------------ files

    def _may_discard(self) -> bool:
        if not self.document.modified:
            return True
        name = self.document.main.path.name if self.document.main.path else "untitled"
        answer = self.ask(self, name)
        if answer == QMessageBox.StandardButton.Save:
            return self.save()
        return answer == QMessageBox.StandardButton.Discard

    def new(self) -> None:
        """Start an empty configuration, after asking about unsaved changes."""
        if self._may_discard():
            self._open_document(Workspace(None, parent=self))

    def open_path(self, path: Path) -> bool:
        """Open the configuration at ``path`` with the files it includes.

        Returns:
            False when the user kept the unsaved changes or the file could not be read (a message says why).
        """
        if not self._may_discard():
            return False
        try:
            document = Workspace(path, parent=self)
        except (OSError, ValueError) as exc:  # lxml's XMLSyntaxError is a ValueError
            QMessageBox.warning(self, "Cannot open", f"{path}: {exc}")
            return False
        self._open_document(document)
        self._remember(path)
        return True

    def open_dialog(self) -> None:
        """Ask for a configuration file and open it."""
        chosen, _ = QFileDialog.getOpenFileName(self, "Open configuration", "", "CKM configurations (*.xml)")
        if chosen:
            self.open_path(Path(chosen))

    def save(self) -> bool:
        """Save every modified file of the configuration (the main one always)."""
        if self.document.main.path is None:
            return self.save_as_dialog()
        self.document.save_all()
        self._remember(self.document.main.path)
        return True

    def save_as(self, path: Path) -> None:
        """The main file under a new name; included files are saved where they are (their hrefs stay valid
        when the new name is in the same folder)."""
        self.document.main.save(path.resolve())
        self.document.save_all()
        self._remember(path)

    def save_as_dialog(self) -> bool:
        """Ask for a file name and save the main file under it; False when cancelled."""
        chosen, _ = QFileDialog.getSaveFileName(self, "Save configuration", "", "CKM configurations (*.xml)")
        if not chosen:
            return False
        self.save_as(Path(chosen))
        return True

    def recent(self) -> list[str]:
        """The recently opened or saved files, newest first (from the settings)."""
        value = self.settings.value("recent", [])
        items = [value] if isinstance(value, str) else list(value) if isinstance(value, list | tuple) else []
        return [str(v) for v in items]

    def _remember(self, path: Path) -> None:
        entries = [str(path.resolve())] + [p for p in self.recent() if p != str(path.resolve())]
        self.settings.setValue("recent", entries[:MAX_RECENT])
        self._fill_recent()

    def _fill_recent(self) -> None:
        self.recent_menu.clear()
        for entry in self.recent():
            action = self.recent_menu.addAction(entry)
            action.triggered.connect(lambda _=False, p=entry: self.open_path(Path(p)))
        self.recent_menu.setEnabled(bool(self.recent_menu.actions()))

    def closeEvent(self, event: QCloseEvent) -> None:
        """Close the window unless the user keeps unsaved changes; stop the live views and the transport."""
        if self._may_discard():
            self.agents.timer.stop()
            self.monitor.timer.stop()
            self.monitor.ros.stop()  # closes the Zenoh session it opened, if any
            if self._transport is not None:
                self._transport.stop()
                self._transport = None
            event.accept()
        else:
            event.ignore()

    # ------------------------------------------------------------------ screenshots

    def show_view(self, view: str) -> None:
        """Bring ``view`` forward: tree, topics, plan, monitor, mission:NAME or element:NAME."""
        if view.startswith("mission:"):
            self.open_mission(view.split(":", 1)[1])
        elif view.startswith("element:"):  # the first element of that name, its form in front
            name = view.split(":", 1)[1]
            found = next((e for d in self.document.all() for e in d.root.iter() if e.get("name") == name), None)
            self.tree.select(found)
            self.tabs.setCurrentIndex(0)
        elif view == "topics":
            self.tabs.setCurrentWidget(self.topics)
        elif view == "plan":
            self.tabs.setCurrentWidget(self.plan)
        elif view == "monitor":
            self.tabs.setCurrentWidget(self.monitor)
        else:
            self.tabs.setCurrentIndex(0)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the configuration editor (§3.1.5.3, graphic configuration interface); ``ckm-editor``'s entry point.

    Returns:
        The process exit code.
    """
    parser = argparse.ArgumentParser(prog="ckm-editor", description="Edit, validate and distribute CKM configurations.")
    parser.add_argument("file", nargs="?", type=Path, help="configuration to open")
    parser.add_argument("--screenshot", type=Path, help="render the window offscreen to this PNG and exit")
    parser.add_argument(
        "--view", default="tree", help="with --screenshot: tree, element:NAME, mission:NAME, topics, plan or monitor"
    )
    args = parser.parse_args(argv)
    if args.screenshot is not None:
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    if args.file is not None and not args.file.is_file():
        print(f"ckm-editor: {args.file}: no such file", file=sys.stderr)
        return 1
    app = QApplication.instance() or QApplication(sys.argv[:1])
    settings = None
    if args.screenshot is not None:  # a screenshot leaves the user's recent files alone
        scratch = Path(os.environ.get("TMPDIR", "/tmp")) / "ckm-editor-screenshot.ini"
        settings = QSettings(str(scratch), QSettings.Format.IniFormat)
    window = MainWindow(args.file, settings=settings)
    window.show()
    if args.screenshot is not None:
        window.show_view(args.view)
        for _ in range(3):
            app.processEvents()
        if args.view.startswith("mission:"):
            window.canvas.fit()
        elif args.view in ("topics", "plan"):
            getattr(window, args.view).fit()
        elif args.view == "monitor":  # what the running system publishes meanwhile
            deadline = time.monotonic() + MONITOR_WAIT
            while time.monotonic() < deadline:
                app.processEvents()
                time.sleep(0.02)
            window.monitor.refresh()
            window.monitor.live.map.fit()
        app.processEvents()
        saved = window.grab().save(str(args.screenshot))
        window.close()  # leaves the network, if the view joined it
        if not saved:
            print(f"ckm-editor: cannot write {args.screenshot}", file=sys.stderr)
            return 1
        return 0
    return app.exec()


if __name__ == "__main__":
    sys.exit(main())
