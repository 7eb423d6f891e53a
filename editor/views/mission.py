"""The mission canvas: an HFSM drawn on a QGraphicsScene (thesis §5.2, Fig. 5.4, Fig. 7.12).

States are rounded boxes (behavior states show their behavior; a state running a nested mission
has a double frame — double-click opens it), finals are ringed circles, the initial state gets
the black dot of statecharts, transitions are one-way arrows labelled with their condition (a
transition back to an earlier column curves, so retries stay readable). Layout: columns by the
shortest distance from the initial state, rows in document order; boxes can be dragged.
Drag with the right button (or Shift + left) from one state onto another to add a transition;
right-click on the empty canvas to add a state. Every change goes through the document's undo
stack, and the canvas redraws from the document.
"""

from __future__ import annotations

import collections
import math

from PySide6.QtCore import QLineF, QPointF, QRectF, Qt, Signal
from PySide6.QtGui import QBrush, QColor, QFont, QMouseEvent, QPainter, QPainterPath, QPen, QPolygonF
from PySide6.QtWidgets import (
    QGraphicsEllipseItem,
    QGraphicsItem,
    QGraphicsPathItem,
    QGraphicsScene,
    QGraphicsSimpleTextItem,
    QGraphicsView,
    QMenu,
    QWidget,
)

from ..document import Element, local
from ..workspace import Workspace

BOX_W, BOX_H, FINAL_R = 150.0, 54.0, 18.0
COL, ROW = 300.0, 110.0
LABEL_MAX = 34  # characters of a condition drawn on its arrow; the whole of it is the tooltip
STATE_FILL, NESTED_FILL, FINAL_FILL = QColor("#e3f2fd"), QColor("#fff3e0"), QColor("#e8f5e9")


def layout(mission: Element) -> dict[str, QPointF]:
    """Columns by BFS distance from the initial state, rows in document order within a column."""
    import networkx as nx  # type: ignore[import-untyped]  # here: opening the editor does not need it

    names = [e.get("name", "") for e in mission if isinstance(e.tag, str) and local(e) in ("State", "Final")]
    graph = nx.DiGraph()
    graph.add_node(mission.get("initial", ""))
    graph.add_edges_from(
        (t.get("from", ""), t.get("to", "")) for t in mission if isinstance(t.tag, str) and local(t) == "Transition"
    )
    depth: dict[str, int] = nx.single_source_shortest_path_length(graph, mission.get("initial", ""))
    last = max(depth.values(), default=0) + 1
    rows: dict[int, int] = collections.defaultdict(int)
    places = {}
    for name in names:
        column = depth.get(name, last)
        places[name] = QPointF(column * COL, rows[column] * ROW)
        rows[column] += 1
    return places


class NodeItem(QGraphicsPathItem):
    """A state or a final; moving it moves its arrows."""

    def __init__(self, canvas: MissionCanvas, element: Element, final: bool) -> None:
        super().__init__()
        self.canvas, self.element, self.final = canvas, element, final
        self.name = element.get("name", "")
        path = QPainterPath()
        if final:
            path.addEllipse(QRectF(-FINAL_R, -FINAL_R, 2 * FINAL_R, 2 * FINAL_R))
            self.setBrush(QBrush(FINAL_FILL))
        else:
            path.addRoundedRect(QRectF(-BOX_W / 2, -BOX_H / 2, BOX_W, BOX_H), 12, 12)
            nested = element.get("mission") is not None
            self.setBrush(QBrush(NESTED_FILL if nested else STATE_FILL))
        self.setPath(path)
        self.setPen(QPen(QColor("#37474f"), 1.6))
        self.setFlags(QGraphicsItem.GraphicsItemFlag.ItemIsMovable | QGraphicsItem.GraphicsItemFlag.ItemIsSelectable
                      | QGraphicsItem.GraphicsItemFlag.ItemSendsGeometryChanges)  # fmt: skip
        self.setZValue(1)
        self._decorate()

    def _decorate(self) -> None:
        element = self.element
        if self.final:
            ring = QGraphicsEllipseItem(QRectF(-FINAL_R + 5, -FINAL_R + 5, 2 * FINAL_R - 10, 2 * FINAL_R - 10), self)
            ring.setPen(QPen(QColor("#37474f"), 1.2))
            text = QGraphicsSimpleTextItem(self.name, self)
            text.setPos(-text.boundingRect().width() / 2, FINAL_R + 2)
            return
        if element.get("mission") is not None:
            inner = QGraphicsPathItem(self)
            path = QPainterPath()
            path.addRoundedRect(QRectF(-BOX_W / 2 + 4, -BOX_H / 2 + 4, BOX_W - 8, BOX_H - 8), 9, 9)
            inner.setPath(path)
            inner.setPen(QPen(QColor("#37474f"), 1.0))
        title = QGraphicsSimpleTextItem(self.name, self)
        font = QFont()
        font.setBold(True)
        title.setFont(font)
        title.setPos(-title.boundingRect().width() / 2, -BOX_H / 2 + 8)
        detail = element.get("behavior") or (f"▸ {element.get('mission')}" if element.get("mission") else "")
        if element.get("timeout"):
            detail += f"  (≤ {element.get('timeout')} s)"
        sub = QGraphicsSimpleTextItem(detail, self)
        sub.setBrush(QBrush(QColor("#546e7a")))
        sub.setPos(-sub.boundingRect().width() / 2, 4)

    def boundary(self, toward: QPointF) -> QPointF:
        """Where a line from the centre toward ``toward`` leaves the shape."""
        centre = self.scenePos()
        dx, dy = toward.x() - centre.x(), toward.y() - centre.y()
        if self.final:
            length = math.hypot(dx, dy) or 1.0
            return QPointF(centre.x() + dx / length * FINAL_R, centre.y() + dy / length * FINAL_R)
        scale = min(BOX_W / 2 / abs(dx) if dx else math.inf, BOX_H / 2 / abs(dy) if dy else math.inf)
        return QPointF(centre.x() + dx * scale, centre.y() + dy * scale)

    def itemChange(self, change: QGraphicsItem.GraphicsItemChange, value: object) -> object:
        """Remember the state's position and reroute the arrows when it moves."""
        if change == QGraphicsItem.GraphicsItemChange.ItemPositionHasChanged:
            self.canvas.positions[(self.canvas.mission_name, self.name)] = self.pos()
            self.canvas.route()
        return super().itemChange(change, value)

    def mouseDoubleClickEvent(self, event: object) -> None:
        """Open the nested mission of a state that has one."""
        nested = self.element.get("mission")
        if nested:
            self.canvas.open_mission.emit(nested)


class ArrowItem(QGraphicsPathItem):
    """A transition: a line or a curve with an arrow head and its condition."""

    def __init__(self, element: Element, source: NodeItem, target: NodeItem, bend: float) -> None:
        super().__init__()
        self.element, self.source, self.target, self.bend = element, source, target, bend
        self.setPen(QPen(QColor("#455a64"), 1.3))
        when = element.get("when", "done()")
        shown = when if len(when) <= LABEL_MAX else when[: LABEL_MAX - 1] + "…"
        self.label = QGraphicsSimpleTextItem(shown, self)
        self.setToolTip(f"{element.get('from')} → {element.get('to')} when {when}")
        self.label.setBrush(QBrush(QColor("#1a237e")))
        font = QFont()
        font.setPointSizeF(7.5)
        self.label.setFont(font)
        self.update_path()

    def update_path(self) -> None:
        """Redraw the arrow between its states' current positions."""
        a, b = self.source.scenePos(), self.target.scenePos()
        middle = QPointF((a.x() + b.x()) / 2, (a.y() + b.y()) / 2)
        normal = QPointF(-(b.y() - a.y()), b.x() - a.x())
        length = math.hypot(normal.x(), normal.y()) or 1.0
        control = middle + normal * (self.bend / length)
        start, end = self.source.boundary(control), self.target.boundary(control)
        path = QPainterPath(start)
        path.quadTo(control, end)
        angle = math.atan2(end.y() - control.y(), end.x() - control.x())
        head = QPolygonF([end, end - QPointF(math.cos(angle - 0.4), math.sin(angle - 0.4)) * 10,
                          end - QPointF(math.cos(angle + 0.4), math.sin(angle + 0.4)) * 10, end])  # fmt: skip
        path.addPolygon(head)
        self.setPath(path)
        peak = path.pointAtPercent(0.5)
        self.label.setPos(peak.x() - self.label.boundingRect().width() / 2, peak.y() - 14)


class MissionCanvas(QGraphicsView):
    """Shows and edits one mission (see the module docstring)."""

    open_mission = Signal(str)
    selected = Signal(object)

    def __init__(self, document: Workspace, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.document = document
        self.setScene(QGraphicsScene(self))
        self.setRenderHints(QPainter.RenderHint.Antialiasing | QPainter.RenderHint.TextAntialiasing)
        self.mission: Element | None = None
        self.mission_name = ""
        self.nodes: dict[str, NodeItem] = {}
        self.arrows: list[ArrowItem] = []
        self.positions: dict[tuple[str, str], QPointF] = {}
        self._drag_from: NodeItem | None = None
        self.active: str | None = None  # highlighted by the monitor
        document.structure_changed.connect(self.redraw)
        document.changed.connect(lambda element: self.redraw() if self._mine(element) else None)

    def _mine(self, element: Element) -> bool:
        return self.mission is not None and (element is self.mission or element.getparent() is self.mission)

    def show_mission(self, mission: Element | None) -> None:
        """Show ``mission`` (ckm.xsd ``Mission``, a hierarchical FSM, §5.2)."""
        self.mission = mission
        self.mission_name = mission.get("name", "") if mission is not None else ""
        self.redraw()
        self.fit()

    def fit(self) -> None:
        """Fit the view to the states drawn."""
        rect = self.scene().itemsBoundingRect().adjusted(-40, -40, 40, 40)
        self.setSceneRect(rect)
        self.fitInView(rect, Qt.AspectRatioMode.KeepAspectRatio)

    def redraw(self) -> None:
        """Draw the mission's states and transitions again from the document."""
        scene = self.scene()
        scene.clear()
        self.nodes, self.arrows = {}, []
        mission = self.mission
        if mission is None or self.document.document_of(mission) is None:
            return
        places = layout(mission)
        for element in mission:
            if isinstance(element.tag, str) and local(element) in ("State", "Final"):
                item = NodeItem(self, element, local(element) == "Final")
                name = element.get("name", "")
                item.setPos(self.positions.get((self.mission_name, name), places.get(name, QPointF())))
                if name == self.active:
                    item.setPen(QPen(QColor("#d84315"), 3.5))
                scene.addItem(item)
                self.nodes[name] = item
        pairs: collections.Counter[frozenset[str]] = collections.Counter()
        for element in mission:
            if not (isinstance(element.tag, str) and local(element) == "Transition"):
                continue
            source, target = self.nodes.get(element.get("from", "")), self.nodes.get(element.get("to", ""))
            if source is None or target is None:
                continue
            key = frozenset((source.name, target.name))
            backward = target.scenePos().x() <= source.scenePos().x()
            bend = (40.0 if backward else 0.0) + 28.0 * pairs[key]
            pairs[key] += 1
            arrow = ArrowItem(element, source, target, bend)
            scene.addItem(arrow)
            self.arrows.append(arrow)
        initial = self.nodes.get(mission.get("initial", ""))
        if initial is not None:
            dot = scene.addEllipse(QRectF(-7, -7, 14, 14), QPen(Qt.PenStyle.NoPen), QBrush(QColor("#212121")))
            start = initial.scenePos() - QPointF(BOX_W / 2 + 40, 0)
            dot.setPos(start)
            scene.addLine(QLineF(start + QPointF(7, 0), initial.scenePos() - QPointF(BOX_W / 2, 0)),
                          QPen(QColor("#212121"), 1.5))  # fmt: skip

    def route(self) -> None:
        """Redraw every arrow."""
        for arrow in self.arrows:
            arrow.update_path()

    def highlight(self, state: str | None) -> None:
        """Mark the active state (the monitor shows a live mission this way)."""
        self.active = state
        self.redraw()

    # ------------------------------------------------------------------ editing

    def connect_states(self, source: str, target: str, when: str = "done()") -> Element | None:
        """Add the transition ``source → target`` (undoable); None for a transition out of a final."""
        mission = self.mission
        if mission is None or source == target or self.nodes.get(source) is None or self.nodes[source].final:
            return None
        transition = self.document.new_element("Transition", {"from": source, "to": target, "when": when})
        last = max(
            (i for i, e in enumerate(mission) if isinstance(e.tag, str) and local(e) == "Transition"), default=-1
        )
        index = last + 1 if last >= 0 else len(mission)
        self.document.insert(mission, index, transition)
        return transition

    def add_state(self, name: str | None = None, at: QPointF | None = None) -> Element | None:
        """Add a ``State`` to the mission (undoable), named ``name`` or the first free ``STATE<n>``.

        Returns:
            The new element, or None when no mission is shown.
        """
        mission = self.mission
        if mission is None:
            return None
        existing = {e.get("name") for e in mission if isinstance(e.tag, str)}
        number = 1
        while name is None or name in existing:
            name, number = f"STATE{number}", number + 1
        state = self.document.new_element("State", {"name": name})
        after = [i for i, e in enumerate(mission) if isinstance(e.tag, str) and local(e) == "State"]
        if at is not None:
            self.positions[(self.mission_name, name)] = at
        self.document.insert(mission, (after[-1] + 1) if after else 0, state)
        return state

    def _node_at(self, event: QMouseEvent) -> NodeItem | None:
        for item in self.items(event.position().toPoint()):
            while item is not None and not isinstance(item, NodeItem):
                item = item.parentItem()
            if isinstance(item, NodeItem):
                return item
        return None

    def mousePressEvent(self, event: QMouseEvent) -> None:
        """Start a link from a state (right or shift-click), offer to add a state (right-click on space), or select."""
        node = self._node_at(event)
        linking = event.button() == Qt.MouseButton.RightButton or (
            event.button() == Qt.MouseButton.LeftButton and event.modifiers() & Qt.KeyboardModifier.ShiftModifier
        )
        if node is not None and linking:
            self._drag_from = node
            return
        if node is None and event.button() == Qt.MouseButton.RightButton and self.mission is not None:
            menu = QMenu(self)
            spot = self.mapToScene(event.position().toPoint())
            menu.addAction("Add state here").triggered.connect(lambda: self.add_state(at=spot))
            menu.exec(event.globalPosition().toPoint())
            return
        if node is not None:
            self.selected.emit(node.element)
        super().mousePressEvent(event)

    def mouseReleaseEvent(self, event: QMouseEvent) -> None:
        """Finish a link: a ``Transition`` between the two states."""
        if self._drag_from is not None:
            target = self._node_at(event)
            source, self._drag_from = self._drag_from, None
            if target is not None and target is not source:
                self.connect_states(source.name, target.name)
            return
        super().mouseReleaseEvent(event)
