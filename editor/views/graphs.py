"""Two read-only views of the loaded system: the topic graph and the plan view.

Topic graph: who publishes and who subscribes each topic across nodes — producers on the left
(sensors, controller outputs, service outputs, behavior outputs), topics in the middle,
consumers on the right (controller inputs, actuators, service inputs, behavior inputs).

Plan view (§5.3, Fig. 5.6, Fig. 7.13): each plan's agents with the node they run on and their
mission, and each signal as an arrow from the agent that emits it (state and moment) to the
agents whose states depend on it.
"""

from __future__ import annotations

import collections

from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtGui import QBrush, QColor, QFont, QPainter, QPen
from PySide6.QtWidgets import QGraphicsScene, QGraphicsSimpleTextItem, QGraphicsView, QWidget

from ckmconf.model import System

PALETTE = ["#bbdefb", "#c8e6c9", "#ffe0b2", "#f8bbd0", "#d1c4e9", "#b2ebf2", "#fff9c4", "#d7ccc8"]


def topic_edges(system: System) -> tuple[list[tuple[str, str, str]], list[tuple[str, str, str]]]:
    """(producer, topic, owner) and (topic, consumer, owner) pairs; owner colours the box."""
    produce: list[tuple[str, str, str]] = []
    consume: list[tuple[str, str, str]] = []
    for node in system.nodes:
        for sensor in node.sensors:
            produce.append((f"{node.name}/{sensor.name}", sensor.topic, node.name))
        for controller in node.controllers:
            label = f"{node.name}/{controller.name}"
            consume += [(c_in.topic, label, node.name) for c_in in controller.inputs]
            produce += [(label, c_out.topic, node.name) for c_out in controller.outputs]
        for actuator in node.actuators:
            consume.append((actuator.topic, f"{node.name}/{actuator.name}", node.name))
    for resource in system.resources:
        for service in resource.services:
            label = f"{resource.name}.{service.name}"
            consume += [(s_in.topic, label, resource.node) for s_in in service.inputs]
            produce += [(label, s_out.topic, resource.node) for s_out in service.outputs]
    for behavior in system.behaviors:
        label = f"behavior {behavior.name}"
        consume += [(b_in.topic, label, "behaviors") for b_in in behavior.inputs if b_in.topic]
        produce += [(label, b_out.topic, "behaviors") for b_out in behavior.outputs if b_out.topic]
    return produce, consume


class _Board(QGraphicsView):
    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setScene(QGraphicsScene(self))
        self.setRenderHints(QPainter.RenderHint.Antialiasing | QPainter.RenderHint.TextAntialiasing)
        self.colours: dict[str, QColor] = {}

    def colour(self, owner: str) -> QColor:
        if owner not in self.colours:
            self.colours[owner] = QColor(PALETTE[len(self.colours) % len(PALETTE)])
        return self.colours[owner]

    def box(self, text: str, at: QPointF, fill: QColor, width: float = 190.0) -> QRectF:
        label = QGraphicsSimpleTextItem(text)
        rect = QRectF(at.x(), at.y(), max(width, label.boundingRect().width() + 16), 24)
        self.scene().addRect(rect, QPen(QColor("#607d8b")), QBrush(fill))
        label.setPos(rect.x() + 8, rect.y() + 4)
        self.scene().addItem(label)
        return rect

    def fit(self) -> None:
        rect = self.scene().itemsBoundingRect().adjusted(-20, -20, 20, 20)
        self.setSceneRect(rect)
        self.fitInView(rect, Qt.AspectRatioMode.KeepAspectRatio)


class TopicGraph(_Board):
    """Producers → topics → consumers of the loaded system."""

    def show_system(self, system: System | None) -> None:
        """Draw producers, topics and consumers of ``system`` (a message when it does not load)."""
        scene = self.scene()
        scene.clear()
        if system is None:
            scene.addSimpleText("The configuration does not load: see the problems.")
            return
        produce, consume = topic_edges(system)
        topics = sorted({t for _, t, _ in produce} | {t for t, _, _ in consume})
        producers = list(dict.fromkeys(p for p, _, _ in produce))
        consumers = list(dict.fromkeys(c for _, c, _ in consume))
        owner = {p: o for p, _, o in produce} | {c: o for _, c, o in consume}
        step = 30.0
        left = {p: self.box(p, QPointF(0, i * step), self.colour(owner[p])) for i, p in enumerate(producers)}
        middle = {t: self.box(t, QPointF(320, i * step), QColor("#eceff1"), 170) for i, t in enumerate(topics)}
        right = {c: self.box(c, QPointF(620, i * step), self.colour(owner[c])) for i, c in enumerate(consumers)}
        pen = QPen(QColor("#90a4ae"), 1.0)
        for p, t, _ in produce:
            a, b = left[p], middle[t]
            scene.addLine(a.right(), a.center().y(), b.left(), b.center().y(), pen)
        for t, c, _ in consume:
            a, b = middle[t], right[c]
            scene.addLine(a.right(), a.center().y(), b.left(), b.center().y(), pen)
        self.fit()


class PlanView(_Board):
    """Agents, their missions, and the signals between them."""

    def show_system(self, system: System | None) -> None:
        """Draw each plan of ``system``: its agents, nodes, missions and signals (§5.3)."""
        scene = self.scene()
        scene.clear()
        if system is None or not system.plans:
            scene.addSimpleText("No plan in this configuration." if system is not None else "Does not load.")
            return
        y = 0.0
        bold = QFont()
        bold.setBold(True)
        for plan in system.plans:
            title = scene.addSimpleText(f"Plan {plan.name}  (an agent silent for {plan.lost_after:g} s is lost)")
            title.setFont(bold)
            title.setPos(0, y)
            y += 30
            boxes = {}
            for i, agent in enumerate(plan.agents):
                rect = QRectF(i * 330.0, y, 280.0, 70.0)
                scene.addRect(rect, QPen(QColor("#455a64"), 1.5), QBrush(self.colour(agent.node)))
                text = scene.addSimpleText(f"{agent.name}\non {agent.node}\nmission {agent.mission}")
                text.setPos(rect.x() + 10, rect.y() + 6)
                boxes[agent.name] = rect
            waits = collections.defaultdict(list)
            for dependency in plan.dependencies:
                waits[dependency.signal].append(dependency)
            row = y + 90
            for signal in plan.signals:
                source = boxes.get(signal.agent)
                for dependency in waits.get(signal.name, []):
                    target = boxes.get(dependency.agent)
                    if source is None or target is None:
                        continue
                    a = QPointF(source.center().x(), source.bottom())
                    b = QPointF(target.center().x(), target.bottom())
                    pen = QPen(QColor("#c62828"), 1.8)
                    scene.addLine(a.x(), a.y(), a.x(), row, pen)
                    scene.addLine(a.x(), row, b.x(), row, pen)
                    scene.addLine(b.x(), row, b.x(), b.y() + 2, pen)
                    scene.addLine(b.x(), b.y() + 2, b.x() - 6, b.y() + 12, pen)
                    scene.addLine(b.x(), b.y() + 2, b.x() + 6, b.y() + 12, pen)
                    label = scene.addSimpleText(
                        f"signal {signal.name}: {signal.agent}/{signal.state} on {signal.on} → "
                        f"{dependency.agent}/{dependency.state} waits"
                    )
                    label.setBrush(QBrush(QColor("#b71c1c")))
                    label.setPos(min(a.x(), b.x()) + 8, row + 4)
                    row += 34
            y = row + 40
        self.fit()
