"""Records of the environment model (schemas/environment.xsd, thesis §6.1)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..binding import Record, attr, child, children

FOOTPRINT_HEIGHT = 0.75
"""Height (m) of a ``<Geometry2D>`` without ``height``: the block the simulated world stands it as (a desk, D85)."""


@dataclass(frozen=True, kw_only=True)
class Vertex(Record):
    """<Vertex>: a polygon point, metres."""

    TAG = "Vertex"
    x: float = attr()
    y: float = attr()


@dataclass(frozen=True, kw_only=True)
class MapBounds(Record):
    """<Map>: the global map bounds (§6.1.2)."""

    TAG = "Map"
    xmin: float = attr()
    ymin: float = attr()
    xmax: float = attr()
    ymax: float = attr()
    height: float = attr(default=3.0)
    image: str | None = attr(default=None)
    resolution: float | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class Region(Record):
    """A named polygon."""

    name: str = attr()
    vertices: tuple[Vertex, ...] = children()

    def points(self) -> list[tuple[float, float]]:
        """The polygon's ``<Vertex>`` elements as (x, y) pairs, in order."""
        return [(v.x, v.y) for v in self.vertices]


@dataclass(frozen=True, kw_only=True)
class Area(Region):
    """<Area>: a room or zone of the map."""

    TAG = "Area"


@dataclass(frozen=True, kw_only=True)
class AvoidedArea(Region):
    """<AvoidedArea>: a place robots cannot enter (a column, a wall); ``height`` m tall (None: the map's, D294)."""

    TAG = "AvoidedArea"
    height: float | None = attr(default=None)

    def top(self, map_height: float) -> float:
        """How tall the area stands (m): its ``height``, else the map's (the sim extrudes it so far)."""
        return map_height if self.height is None else self.height


@dataclass(frozen=True, kw_only=True)
class Texture(Record):
    """<Texture>: an object's appearance (§6.1.1.1)."""

    TAG = "Texture"
    name: str = attr()
    pattern: Literal["plain", "stripes", "checker", "dots", "label", "image"] = attr(default="plain")
    color: str = attr(default="#808080")
    secondary: str | None = attr(default=None)
    image: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class Affordance(Record):
    """<Affordance>: an interaction a robot may have with objects of a tag."""

    TAG = "Affordance"
    action: str = attr()
    condition: str | None = attr(default=None)
    mission: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class Semantic(Record):
    """<Semantic>: an entry of the semantic dictionary (§6.1.1.2)."""

    TAG = "Semantic"
    tag: str = attr()
    landmark: Literal["landmark", "restricted-area", "free"] = attr(default="free")
    dynamic: Literal["static", "mobile"] = attr(default="static")
    max_speed: float | None = attr(default=None)
    axes: tuple[str, ...] | None = attr(default=None)
    description: str | None = attr(default=None)
    affordances: tuple[Affordance, ...] = children()


@dataclass(frozen=True, kw_only=True)
class Pose(Record):
    """<Pose>: position (m) and heading (rad) in the map frame."""

    TAG = "Pose"
    x: float = attr()
    y: float = attr()
    z: float = attr(default=0.0)
    yaw: float = attr(default=0.0)


@dataclass(frozen=True, kw_only=True)
class Circle(Record):
    """<Circle>: a 2D atomic element."""

    TAG = "Circle"
    x: float = attr(default=0.0)
    y: float = attr(default=0.0)
    radius: float = attr()


@dataclass(frozen=True, kw_only=True)
class Rectangle(Record):
    """<Rectangle>: a 2D atomic element (width along x, depth along y before yaw)."""

    TAG = "Rectangle"
    x: float = attr(default=0.0)
    y: float = attr(default=0.0)
    width: float = attr()
    depth: float = attr()
    yaw: float = attr(default=0.0)


@dataclass(frozen=True, kw_only=True)
class Polygon(Record):
    """<Polygon>: a 2D atomic element."""

    TAG = "Polygon"
    vertices: tuple[Vertex, ...] = children()


Atom2D = Circle | Rectangle | Polygon


@dataclass(frozen=True, kw_only=True)
class Prism(Record):
    """<Prism>: a 2.5D atomic element, a 2D element extruded from zmin to zmax."""

    TAG = "Prism"
    zmin: float = attr(default=0.0)
    zmax: float = attr()
    base: Atom2D = child()


@dataclass(frozen=True, kw_only=True)
class Geometry2D(Record):
    """<Geometry2D>: one or more 2D atomic elements, ``height`` m tall (D294).

    ``height`` absent: a :data:`FOOTPRINT_HEIGHT` block in the simulated world (the planner's map keeps it
    an obstacle at every height, §6.1.1.1); ``0``: a marking, drawn on the floor and nobody's obstacle.
    """

    TAG = "Geometry2D"
    height: float | None = attr(default=None)
    atoms: tuple[Atom2D, ...] = children()

    @property
    def marking(self) -> bool:
        """Whether the geometry is flat (``height="0"``): a landing pad, a dock marking."""
        return self.height == 0

    @property
    def solid_height(self) -> float:
        """How tall the object stands in the world (m): its ``height``, else :data:`FOOTPRINT_HEIGHT`."""
        return FOOTPRINT_HEIGHT if self.height is None else self.height


@dataclass(frozen=True, kw_only=True)
class Geometry25D(Record):
    """<Geometry25D>: exactly one 2.5D atomic element."""

    TAG = "Geometry25D"
    prism: Prism = child()


@dataclass(frozen=True, kw_only=True)
class Geometry3D(Record):
    """<Geometry3D>: one or more 2.5D atomic elements."""

    TAG = "Geometry3D"
    prisms: tuple[Prism, ...] = children()


Geometry = Geometry2D | Geometry25D | Geometry3D


@dataclass(frozen=True, kw_only=True)
class EnvObject(Record):
    """<Object>: an environment object (§6.1.1)."""

    TAG = "Object"
    name: str = attr()
    tag: str = attr()
    texture: str | None = attr(default=None)
    area: str | None = attr(default=None)
    stamp: str | None = attr(default=None)
    pose: Pose = child()
    geometry: Geometry = child()


@dataclass(frozen=True, kw_only=True)
class ZoomMap(Record):
    """<ZoomMap>: the attention area settings (§6.1.3)."""

    TAG = "ZoomMap"
    mode: Literal["2D", "2.5D"] = attr(default="2D")
    width: float = attr()
    depth: float = attr()
    height: float | None = attr(default=None)
    border: float = attr(default=0.1)
    timeout: float = attr(default=10.0)
    max_objects: int | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class Environment(Record):
    """<Environment>: the map, areas, textures, semantics, objects and Zoom Map (§6.1)."""

    TAG = "Environment"
    name: str = attr()
    frame: str = attr(default="map")
    map: MapBounds = child()
    areas: tuple[Area, ...] = children()
    avoided: tuple[AvoidedArea, ...] = children()
    textures: tuple[Texture, ...] = children()
    semantics: tuple[Semantic, ...] = children()
    objects: tuple[EnvObject, ...] = children()
    zoom: ZoomMap | None = child(default=None)
