"""The problems panel: every ConfigError of the lax load, every off-line mission finding and
every plan finding (deadlocks, late signals … of the plans' wait-for graphs).

A click selects the element the problem names (its readable xpath, resolved in the tree).
"""

from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import QListWidget, QListWidgetItem, QWidget

from ..document import Problem
from ..workspace import Workspace

ROLE = Qt.ItemDataRole.UserRole


class ProblemsPanel(QListWidget):
    """Lists the document's problems; ``chosen`` carries the element of a clicked one."""

    chosen = Signal(object)

    def __init__(self, document: Workspace, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.document = document
        document.problems_changed.connect(self.refresh)
        self.itemActivated.connect(self._activate)
        self.itemClicked.connect(self._activate)
        self.refresh()

    def refresh(self) -> None:
        """List the document's problems again (a green line when it validates)."""
        self.clear()
        problems = self.document.problems
        if not problems:
            item = QListWidgetItem("No problems: the configuration validates.")
            item.setForeground(QBrush(QColor("#2e7d32")))
            self.addItem(item)
            return
        for problem in problems:
            item = QListWidgetItem(f"{'⚠' if problem.severity == 'warning' else '✖'} {problem.text()}")
            item.setToolTip(f"{problem.file}:{problem.line}:{problem.column}\n{problem.xpath}\n{problem.message}")
            item.setData(ROLE, problem)
            colour = "#b26a00" if problem.severity == "warning" else "#c62828"
            item.setForeground(QBrush(QColor(colour)))
            self.addItem(item)

    def problems(self) -> list[Problem]:
        """The problems listed, in order."""
        found = []
        for row in range(self.count()):
            problem = self.item(row).data(ROLE)
            if problem is not None:
                found.append(problem)
        return found

    def _activate(self, item: QListWidgetItem) -> None:
        problem: Problem | None = item.data(ROLE)
        if problem is not None:
            element = self.document.find(problem)
            if element is not None:
                self.chosen.emit(element)
