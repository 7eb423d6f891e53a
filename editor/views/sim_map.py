"""The live map of a running simulation in the Monitor tab (issue K.5; Fig. 7.16 of §7.4.1 as it
happens, §6.1 for the environment).

The ``<Environment>`` is drawn once: the map's bounds, its areas (named), the avoided areas
(hatched) and the objects' footprints in their textures' colours. Over it, at every refresh, from
a :class:`~editor.views.sim_state.Snapshot`:

- each robot's **true pose** (a filled arrow, green) and **estimated pose** (an outlined arrow,
  blue) with the **2σ covariance ellipse** of its position, and both trajectories so far; a robot
  with no ground-truth topic is drawn where the configuration placed it (the Nao stands still),
  and where its head's pan turns its camera (dotted) when it publishes its head angles;
- the **particle cloud**, when the system publishes one;
- the **zoom-map area** (dashed, purple), published or replayed (:mod:`.sim_state`);
- the **recognised objects** in the map frame, each labelled with its name and reliability (an
  observation the fusion could not place yet as its camera's ray, dashed; an object singled out on
  an ObjectPosition topic, the Nao's spotted target, with that topic's name).

Scene coordinates are the map's metres × :data:`SCALE`, y pointing up the screen (``to_scene``).
:class:`SimLivePanel` puts the map, the camera images (:mod:`.camera`) and a line saying what the
system does not publish side by side, and subscribes the topics :func:`~.sim_feeds.feeds_of` finds.
"""

from __future__ import annotations

import math

import numpy as np
from PySide6.QtCore import QLineF, QPointF, QRectF, Qt
from PySide6.QtGui import QBrush, QColor, QPainter, QPainterPath, QPen, QPolygonF, QResizeEvent
from PySide6.QtWidgets import (
    QGraphicsEllipseItem,
    QGraphicsItem,
    QGraphicsLineItem,
    QGraphicsPathItem,
    QGraphicsPolygonItem,
    QGraphicsRectItem,
    QGraphicsScene,
    QGraphicsSimpleTextItem,
    QGraphicsView,
    QLabel,
    QScrollArea,
    QSplitter,
    QVBoxLayout,
    QWidget,
)

from ckmconf.model import System
from ckmconf.model.environment import Circle, Environment, EnvObject, Geometry2D, Geometry3D, Polygon, Rectangle
from runtime.network import Subscription, TopicQoS, Transport

from .camera import CameraPanel
from .sim_feeds import Robot, feeds_of
from .sim_state import LiveState, Snapshot, zoom_text

SCALE = 100.0  # scene units per metre
RAY = 2.0  # m of an unplaced sighting's ray drawn from its camera
GAZE = 1.5  # m of a robot's head direction drawn from it
TRUE, ESTIMATE, ZOOM, OBJECT = QColor("#2e7d32"), QColor("#1565c0"), QColor("#8e24aa"), QColor("#e65100")


def to_scene(x: float, y: float) -> QPointF:
    """The scene point of the map point ``(x, y)`` (m)."""
    return QPointF(x * SCALE, -y * SCALE)


def _polygon(points: list[tuple[float, float]]) -> QPolygonF:
    return QPolygonF([to_scene(x, y) for x, y in points])


def _placed(obj: EnvObject, x: float, y: float) -> tuple[float, float]:
    """A point of the object's own frame in the map frame (its ``<Pose>``)."""
    c, s = math.cos(obj.pose.yaw), math.sin(obj.pose.yaw)
    return obj.pose.x + c * x - s * y, obj.pose.y + s * x + c * y


def _footprint(obj: EnvObject) -> QPainterPath:
    """The floor projection of an ``<Object>``'s geometry (every atom, or every prism's base)."""
    geometry = obj.geometry
    atoms = geometry.atoms if isinstance(geometry, Geometry2D) else (
        [p.base for p in geometry.prisms] if isinstance(geometry, Geometry3D) else [geometry.prism.base])  # fmt: skip
    path = QPainterPath()
    for atom in atoms:
        if isinstance(atom, Circle):
            centre, radius = to_scene(*_placed(obj, atom.x, atom.y)), atom.radius * SCALE
            path.addEllipse(centre, radius, radius)
        elif isinstance(atom, Rectangle):
            c, s = math.cos(atom.yaw), math.sin(atom.yaw)
            corners = [(sx * atom.width / 2, sy * atom.depth / 2) for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            path.addPolygon(
                _polygon([_placed(obj, atom.x + c * u - s * v, atom.y + s * u + c * v) for u, v in corners])
            )
            path.closeSubpath()
        elif isinstance(atom, Polygon):
            path.addPolygon(_polygon([_placed(obj, v.x, v.y) for v in atom.vertices]))
            path.closeSubpath()
    return path


def _arrow(color: QColor, filled: bool) -> QGraphicsPolygonItem:
    """A robot marker pointing along +x: 0.4 m long, 0.3 m wide."""
    shape = QPolygonF([QPointF(0.25 * SCALE, 0), QPointF(-0.15 * SCALE, 0.15 * SCALE),
                       QPointF(-0.08 * SCALE, 0), QPointF(-0.15 * SCALE, -0.15 * SCALE)])  # fmt: skip
    item = QGraphicsPolygonItem(shape)
    pen = QPen(color, 2)
    pen.setCosmetic(True)
    item.setPen(pen)
    item.setBrush(QBrush(color) if filled else QBrush(Qt.BrushStyle.NoBrush))
    item.setZValue(20 if filled else 21)
    return item


def _place(item: QGraphicsItem, pose: tuple[float, float, float]) -> None:
    item.setPos(to_scene(pose[0], pose[1]))
    item.setRotation(-math.degrees(pose[2]))  # scene y points down: a map angle turns the other way
    item.setVisible(True)


class SimMapView(QGraphicsView):
    """The environment and the live state over it (see the module docstring)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setScene(QGraphicsScene(self))
        self.setRenderHint(QPainter.RenderHint.Antialiasing)
        self.setDragMode(QGraphicsView.DragMode.ScrollHandDrag)
        self.bounds = QRectF()
        self.robots: dict[str, dict[str, QGraphicsItem]] = {}
        self.labels: list[QGraphicsSimpleTextItem] = []  # the recognised objects' labels (on white plates)
        self._marks: list[QGraphicsItem] = []
        self._where: dict[str, tuple[float, float, float]] = {}  # each robot's last true pose drawn
        self.particles = QGraphicsPathItem()
        self.zoom = QGraphicsRectItem()
        self.zoom_label = QGraphicsSimpleTextItem()

    def show_environment(self, env: Environment | None, robots: tuple[Robot, ...]) -> None:
        """Draw the environment and make the robots' markers (hidden until their first pose)."""
        scene = self.scene()
        scene.clear()
        self.robots, self.labels, self._marks, self._where = {}, [], [], {}
        self.bounds = QRectF()
        thin = QPen(QColor("#424242"), 1)
        thin.setCosmetic(True)
        if env is not None:
            b = env.map
            self.bounds = QRectF(to_scene(b.xmin, b.ymax), to_scene(b.xmax, b.ymin))
            frame = QPen(Qt.GlobalColor.black, 3)
            frame.setCosmetic(True)
            scene.addRect(self.bounds, frame)
            for area in env.areas:
                scene.addPolygon(_polygon(area.points()), QPen(QColor("#2e86c1")), QBrush(QColor("#d6eaf8")))
                self._text(area.name, *min(area.points(), key=lambda p: p[0] - p[1]), QColor("#1b4f72"))
            for avoided in env.avoided:
                scene.addPolygon(
                    _polygon(avoided.points()), thin, QBrush(QColor("#7b7d7d"), Qt.BrushStyle.BDiagPattern)
                )
            colours = {t.name: t.color for t in env.textures}
            marking_pen = QPen(QColor("#555555"), 1, Qt.PenStyle.DashLine)
            marking_pen.setCosmetic(True)
            for obj in env.objects:
                fill = QColor(colours.get(obj.texture or "", "#bbbbbb"))
                flat = isinstance(obj.geometry, Geometry2D) and obj.geometry.marking
                if flat:  # a marking (D294): drawn on the floor, nobody's obstacle: pale, dashed
                    fill.setAlphaF(0.45)
                item = scene.addPath(_footprint(obj), marking_pen if flat else thin, QBrush(fill))
                item.setToolTip(f"{obj.name} ({obj.tag}{', a marking' if flat else ''})")
        self.particles = QGraphicsPathItem()
        self.particles.setBrush(QBrush(QColor(211, 47, 47, 160)))
        self.particles.setPen(QPen(Qt.PenStyle.NoPen))
        self.particles.setZValue(10)
        self.zoom = QGraphicsRectItem()
        dashed = QPen(ZOOM, 2, Qt.PenStyle.DashLine)
        dashed.setCosmetic(True)
        self.zoom.setPen(dashed)
        self.zoom.setZValue(5)
        self.zoom_label = self._text("", 0.0, 0.0, ZOOM)
        overlays: tuple[QGraphicsItem, ...] = (self.particles, self.zoom, self.zoom_label)
        for overlay in overlays:
            overlay.setVisible(False)
            if overlay.scene() is None:
                scene.addItem(overlay)
        for robot in robots:
            markers: dict[str, QGraphicsItem] = {"truth": _arrow(TRUE, True), "estimate": _arrow(ESTIMATE, False)}
            ellipse = QGraphicsEllipseItem()
            pen = QPen(ESTIMATE, 1, Qt.PenStyle.DashLine)
            pen.setCosmetic(True)
            ellipse.setPen(pen)
            ellipse.setBrush(QBrush(QColor(21, 101, 192, 40)))
            ellipse.setZValue(15)
            markers["ellipse"] = ellipse
            markers["label"] = QGraphicsSimpleTextItem(robot.name if robot.truth or robot.estimates
                                                       else f"{robot.name} (placed)")  # fmt: skip
            markers["label"].setZValue(25)
            markers["label"].setFlag(QGraphicsItem.GraphicsItemFlag.ItemIgnoresTransformations)
            for kind, colour in (("truth", TRUE), ("estimate", ESTIMATE)):  # the trajectories so far
                trail = QGraphicsPathItem()
                line = QPen(colour, 1.5)
                line.setCosmetic(True)
                trail.setPen(line)
                trail.setZValue(12)
                markers[f"{kind}_track"] = trail
            gaze = QGraphicsLineItem()
            dotted = QPen(TRUE, 2, Qt.PenStyle.DotLine)
            dotted.setCosmetic(True)
            gaze.setPen(dotted)
            markers["gaze"] = gaze
            for marker in markers.values():
                scene.addItem(marker)
                marker.setVisible(False)
            if robot.truth is None:  # it does not move: its configured placement is its true pose
                _place(markers["truth"], robot.placed)
                self._label(markers["label"], robot.placed)
                self._where[robot.name] = robot.placed
            self.robots[robot.name] = markers
        self.fit()

    def _text(self, text: str, x: float, y: float, colour: QColor) -> QGraphicsSimpleTextItem:
        item = self.scene().addSimpleText(text)
        item.setBrush(QBrush(colour))
        item.setPos(to_scene(x, y))
        item.setZValue(30)
        item.setFlag(QGraphicsItem.GraphicsItemFlag.ItemIgnoresTransformations)  # readable at any zoom
        return item

    @staticmethod
    def _label(label: QGraphicsItem, pose: tuple[float, float, float]) -> None:
        label.setPos(to_scene(pose[0], pose[1]) + QPointF(0.2 * SCALE, 0.1 * SCALE))
        label.setVisible(True)

    def fit(self) -> None:
        """Show the whole map (its bounds with a margin)."""
        if not self.bounds.isNull():
            self.fitInView(self.bounds.adjusted(-30, -30, 30, 30), Qt.AspectRatioMode.KeepAspectRatio)

    def resizeEvent(self, event: QResizeEvent) -> None:
        """Keep the whole map in view as the tab is resized."""
        super().resizeEvent(event)
        self.fit()

    def show_state(self, now: Snapshot) -> None:
        """Move the markers, the ellipses, the cloud and the zoom area; relabel the objects."""
        for name, markers in self.robots.items():
            if name in now.truth:
                _place(markers["truth"], now.truth[name])
                self._label(markers["label"], now.truth[name])
                self._where[name] = now.truth[name]
            if name in now.head and name in self._where:  # where its head (camera) looks
                x, y, yaw = self._where[name]
                end = (x + GAZE * math.cos(yaw + now.head[name]), y + GAZE * math.sin(yaw + now.head[name]))
                gaze = markers["gaze"]
                assert isinstance(gaze, QGraphicsLineItem)
                gaze.setLine(QLineF(to_scene(x, y), to_scene(*end)))
                gaze.setVisible(True)
            if name in now.estimate:
                _place(markers["estimate"], now.estimate[name])
                if name not in now.truth:
                    self._label(markers["label"], now.estimate[name])
            if name in now.covariance and name in now.estimate:
                self._ellipse(markers["ellipse"], now.estimate[name], now.covariance[name])
            for kind in ("truth", "estimate"):
                points = now.tracks.get((name, kind), [])
                trail = markers[f"{kind}_track"]
                if len(points) > 1 and isinstance(trail, QGraphicsPathItem):
                    path = QPainterPath(to_scene(*points[0]))
                    for x, y in points[1:]:
                        path.lineTo(to_scene(x, y))
                    trail.setPath(path)
                    trail.setVisible(True)
        self._cloud(now.particles)
        if now.zoom is not None:
            z = now.zoom
            self.zoom.setRect(QRectF(to_scene(z.x - z.width / 2, z.y + z.depth / 2),
                                     to_scene(z.x + z.width / 2, z.y - z.depth / 2)))  # fmt: skip
            self.zoom_label.setText(zoom_text(z))
            self.zoom_label.setPos(to_scene(z.x - z.width / 2, z.y + z.depth / 2) + QPointF(4, 2))
            self.zoom.setVisible(True)
            self.zoom_label.setVisible(True)
        scene = self.scene()
        for item in self._marks:
            scene.removeItem(item)
        self._marks, self.labels = [], []
        for seen in now.objects:
            at = to_scene(seen.x, seen.y)
            mark: QGraphicsItem
            if seen.ray is None:
                mark = scene.addEllipse(QRectF(-6, -6, 12, 12), QPen(OBJECT, 2), QBrush(QColor(230, 81, 0, 90)))
                mark.setPos(at)
            else:  # a sighting not placed yet: the camera's ray
                pen = QPen(OBJECT, 2, Qt.PenStyle.DashLine)
                pen.setCosmetic(True)
                at = to_scene(seen.x + RAY * seen.ray[0], seen.y + RAY * seen.ray[1])
                mark = scene.addLine(QLineF(to_scene(seen.x, seen.y), at), pen)
            mark.setZValue(26)
            mark.setToolTip(f"{seen.label} from {seen.topic}, {seen.sources} source(s)")
            note = " (ray)" if seen.ray is not None else f" ({seen.topic})" if seen.chosen else ""
            label = QGraphicsSimpleTextItem(f"{seen.label} {seen.reliability:.2f}{note}")
            label.setBrush(QBrush(OBJECT.darker(130)))
            plate = scene.addRect(label.boundingRect().adjusted(-2, 0, 2, 0), QPen(Qt.PenStyle.NoPen),
                                  QBrush(QColor(255, 255, 255, 200)))  # fmt: skip
            label.setParentItem(plate)  # readable over the objects' footprints
            plate.setPos(at + QPointF(8, -16))
            plate.setZValue(30)
            plate.setFlag(QGraphicsItem.GraphicsItemFlag.ItemIgnoresTransformations)
            self._marks += [mark, plate]
            self.labels.append(label)

    @staticmethod
    def _ellipse(item: QGraphicsItem, pose: tuple[float, float, float], covariance: np.ndarray) -> None:
        """The 2σ ellipse of a position covariance, on the estimate."""
        assert isinstance(item, QGraphicsEllipseItem)
        values, vectors = np.linalg.eigh((covariance + covariance.T) / 2)
        major, minor = (2 * math.sqrt(max(float(v), 0.0)) * SCALE for v in (values[1], values[0]))
        item.setRect(QRectF(-major, -minor, 2 * major, 2 * minor))
        item.setPos(to_scene(pose[0], pose[1]))
        item.setRotation(-math.degrees(math.atan2(float(vectors[1, 1]), float(vectors[0, 1]))))
        item.setVisible(True)

    def _cloud(self, cloud: np.ndarray | None) -> None:
        if cloud is None:
            return
        path = QPainterPath()
        dot = 0.03 * SCALE
        for x, y in cloud[:5000]:  # AMCL's clouds are a few thousand particles at most
            path.addRect(QRectF(x * SCALE - dot / 2, -y * SCALE - dot / 2, dot, dot))
        self.particles.setPath(path)
        self.particles.setVisible(True)


class SimLivePanel(QWidget):
    """The live map over the camera images, and a line on what the system does not publish."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.map = SimMapView()
        self.cameras = CameraPanel()
        self.notes = QLabel()
        self.notes.setWordWrap(True)
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setWidget(self.cameras)
        split = QSplitter(Qt.Orientation.Vertical)
        split.addWidget(self.map)
        split.addWidget(scroll)
        split.setSizes([600, 300])
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(split)
        layout.addWidget(self.notes)
        self.system: System | None = None
        self.state: LiveState | None = None
        self._subscriptions: list[Subscription] = []

    def start(self, system: System | None, transport: Transport) -> None:
        """Subscribe the live topics of ``system`` (again only when the system changed)."""
        if system is self.system and self.state is not None:
            return
        self.stop()
        self.system = system
        if system is None:
            return
        feeds = feeds_of(system)
        env = system.environment
        self.state = LiveState(feeds, env.zoom if env is not None else None)
        self.map.show_environment(env, feeds.robots)
        self.cameras.show_topics(feeds.cameras)
        for topic, handler in self.state.handlers().items():
            qos = TopicQoS(topic, feeds.types.get(topic, "bytes"), "best-effort", history=1)
            self._subscriptions.append(transport.subscribe(qos, handler))
        self.notes.setText(self._missing(system))

    def _missing(self, system: System) -> str:
        """What the map cannot show for want of a topic, and where the zoom area comes from."""
        assert self.state is not None
        feeds, out = self.state.feeds, []
        if not feeds.particles:
            where = ", ".join(t for r in feeds.robots for t in r.estimates) or "a pose estimate"
            out.append(f"Particles: not published by this system (drawn from a 'particles' field of {where} "
                       "or a topic named for particles).")  # fmt: skip
        if not feeds.zoom:
            zoom = system.environment.zoom if system.environment is not None else None
            out.append("Zoom map: no topic carries it; " + (
                f"replayed from the estimate with <ZoomMap> ({zoom.width:g}×{zoom.depth:g} m)." if zoom is not None
                else "the environment has no <ZoomMap>."))  # fmt: skip
        for robot in feeds.robots:
            if robot.truth is None:
                out.append(f"{robot.name}: no ground-truth topic, drawn where the configuration places it.")
            if not robot.estimates:
                out.append(f"{robot.name}: no pose estimate published.")
        return " ".join(out)

    def stop(self) -> None:
        """Unsubscribe the live topics (the transport stays: the Monitor tab owns it)."""
        for subscription in self._subscriptions:
            subscription.close()
        self._subscriptions, self.state, self.system = [], None, None

    def refresh(self) -> None:
        """Redraw from the newest values (the Monitor tab's timer calls it on the GUI thread)."""
        if self.state is None:
            return
        now = self.state.snapshot()
        self.map.show_state(now)
        self.cameras.show_frames(now.images)
        if now.errors:
            text = self._missing(self.system) if self.system is not None else ""
            self.notes.setText(text + " Unreadable: " + "; ".join(f"{t}: {e}" for t, e in sorted(now.errors.items())))
