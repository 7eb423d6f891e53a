"""The system tree: every element of the document, named by its tag and name, with add/remove.

Items keep a reference to their lxml element; the tree is rebuilt when the structure changes and
the selection follows the element, not the row. "Add" offers what the XSD allows under the
selected element now (:meth:`SchemaModel.allowed_children`) and inserts it where the content
model wants it, with the attributes it needs to be valid (:meth:`SchemaModel.default_attributes`).
"""

from __future__ import annotations

from PySide6.QtCore import QPoint, Qt, Signal
from PySide6.QtGui import QAction
from PySide6.QtWidgets import QMenu, QTreeWidget, QTreeWidgetItem, QWidget

from ..document import Element, local
from ..model.schema import SchemaModel
from ..workspace import Workspace

ROLE = Qt.ItemDataRole.UserRole


def label(element: Element) -> str:
    """The text of ``element``'s tree item: its tag and its name (or the nearest thing to one)."""
    name = element.get("name") or element.get("ref") or element.get("plugin") or element.get("measure")
    name = name or element.get("href")
    if local(element) == "Transition":
        name = f"{element.get('from')} → {element.get('to')}"
    return f"{local(element)} {name}" if name else local(element)


def parent_tag(element: Element) -> str | None:
    """The tag of ``element``'s parent, or None at the root."""
    parent = element.getparent()
    return None if parent is None else local(parent)


class SystemTree(QTreeWidget):
    """The document's elements (see the module docstring)."""

    selected = Signal(object)  # the selected element

    def __init__(self, document: Workspace, schema: SchemaModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.document, self.schema = document, schema
        self.setHeaderLabels(["Element"])
        self.setContextMenuPolicy(Qt.ContextMenuPolicy.CustomContextMenu)
        self.customContextMenuRequested.connect(self._menu)
        self.currentItemChanged.connect(self._current)
        document.structure_changed.connect(self.rebuild)
        document.changed.connect(self._relabel)
        self._items: dict[int, QTreeWidgetItem] = {}
        self.rebuild()

    # ------------------------------------------------------------------ building

    def rebuild(self) -> None:
        """Rebuild the tree from the documents, keeping the selection and the expanded items."""
        current = self.current_element()
        expanded = {key for key, item in self._items.items() if item.isExpanded()}
        self.blockSignals(True)
        self.clear()
        self._items = {}
        self._shown: set[int] = set()
        root = self._add(None, self.document.main.root)
        self.blockSignals(False)
        for key in expanded or {id(self.document.main.root)}:
            if key in self._items:
                self._items[key].setExpanded(True)
        root.setExpanded(True)
        self.select(current if current is not None else self.document.main.root)

    def _add(self, parent: QTreeWidgetItem | None, element: Element) -> QTreeWidgetItem:
        item = QTreeWidgetItem([label(element)])
        item.setData(0, ROLE, element)
        self._items[id(element)] = item
        if parent is None:
            self.addTopLevelItem(item)
        else:
            parent.addChild(item)
        for child in element:
            if isinstance(child.tag, str):
                self._add(item, child)
        if local(element) == "Include":
            included = self.document.included(element)
            if included is not None and id(included.root) not in self._shown:
                self._shown.add(id(included.root))  # a file included twice is shown once, where first included
                part = self._add(item, included.root)
                part.setText(0, f"{label(included.root)} — {included.path.name if included.path else ''}")
            elif included is not None:
                item.setText(0, f"{label(element)} {element.get('href')} (shown above)")
        return item

    def _relabel(self, element: Element) -> None:
        item = self._items.get(id(element))
        if item is not None:
            item.setText(0, label(element))

    # ------------------------------------------------------------------ selection

    def current_element(self) -> Element | None:
        """The element selected, if any."""
        item = self.currentItem()
        return None if item is None else item.data(0, ROLE)

    def select(self, element: Element | None) -> None:
        """Select ``element``'s item and expand its ancestors."""
        item = self._items.get(id(element)) if element is not None else None
        if item is not None:
            parent = item.parent()
            while parent is not None:
                parent.setExpanded(True)
                parent = parent.parent()
            self.setCurrentItem(item)
            self.scrollToItem(item)

    def _current(self, item: QTreeWidgetItem | None, _previous: QTreeWidgetItem | None) -> None:
        if item is not None:
            self.selected.emit(item.data(0, ROLE))

    # ------------------------------------------------------------------ add / remove

    def addable(self, element: Element) -> list[str]:
        """The child tags the content model still allows under ``element``."""
        existing = [local(c) for c in element if isinstance(c.tag, str)]
        try:
            specs = self.schema.allowed_children(local(element), existing, parent_tag(element))
        except KeyError:
            return []
        return [spec.tag for spec in specs]

    def add_child(self, element: Element, tag: str) -> Element:
        """Insert a new ``tag`` under ``element`` where the content model wants it (undoable)."""
        existing = [local(c) for c in element if isinstance(c.tag, str)]
        position = self.schema.child_position(local(element), existing, tag)
        attributes = self.schema.default_attributes(tag, local(element))
        child = self.document.new_element(tag, attributes)
        elements = [c for c in element if isinstance(c.tag, str)]
        index = list(element).index(elements[position]) if position < len(elements) else len(element)
        self.document.insert(element, index, child)
        self.select(child)
        return child

    def remove_current(self) -> None:
        """Remove the selected element (undoable) and select its parent."""
        element = self.current_element()
        if element is not None and element.getparent() is not None:
            parent = element.getparent()
            self.document.remove(element)
            self.select(parent)

    def _menu(self, position: QPoint) -> None:
        element = self.current_element()
        if element is None:
            return
        menu = QMenu(self)
        add = menu.addMenu("Add")
        for tag in self.addable(element):
            action = QAction(tag, add)
            action.triggered.connect(lambda _=False, t=tag: self.add_child(element, t))
            add.addAction(action)
        add.setEnabled(bool(add.actions()))
        remove = menu.addAction("Remove")
        remove.setEnabled(element.getparent() is not None)
        remove.triggered.connect(self.remove_current)
        menu.exec(self.viewport().mapToGlobal(position))
