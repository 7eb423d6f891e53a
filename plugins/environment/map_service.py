"""``plugin.environment-map``: the environment map as a Smart Resource service shared between robots.

Thesis §6.1.1 (objects with a time mark and a reliability), §6.1.2 (the global map), §4.3 (a
service: Inputs, Outputs, Params). The map is configurable through the plugin's Params: which
``environment`` file (required) and which of its ``areas`` this map holds (empty:
the whole map; otherwise only the objects lying in those Areas are loaded, accepted and shared).

Inputs (any names; each message says what it is):

- a **recognition result** (the fusion service's output, ``/recog/objects``, in the MAP frame:
  ``{"objects": [{"name", "shape", "texture", "x", "y", "z", "reliability", …}], "reliability"}``):
  each positioned object enters the map with its reliability and the message's ``stamp`` (else
  the frame's) as time mark (plugins/environment/perception.py ``ingest_fused``);
- a **map update** of another robot's map service (its ``objects`` Output): ``{"type": "objects",
  "map", "stamp", "objects": [encoded objects]}``; each object replaces the local one only when its
  time mark is newer (ties: the larger source name), so robots exchanging updates in any order end
  with one object list (:meth:`MapModel.replace`). Malformed objects are counted and dropped.

Output ``objects`` (the service's one Output, which publishes the plugin's whole result): a map
update in that shape — the objects changed since the last one (at most ``chunk``), and every
``fullEvery`` frames a further slice of all of them (robots that join late, or missed a best-effort
sample, catch up) — with the measures beside: ``map_objects`` (objects held), ``applied`` (updates
that changed the map this frame), ``rejected`` (malformed received objects so far).

The Smart Resource stream runs a frame only when an input has a fresh sample, so two robots that
only take each other's updates would never start: wire at least one input that publishes on its
own (the robot's recognition result). The same message shape is what
:class:`plugins.environment.sharing.MapShare` publishes, so both interoperate.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from typing import Any, ClassVar

import msgpack
import shapely
from shapely.prepared import prep

from ckmconf.model.resources import Plugin
from plugins.environment_file import environment_of
from runtime.resources import codec
from runtime.resources.spt import Context, ProcessingPlugin, config_dir
from runtime.verification.manifest import ENVIRONMENT_FILE, MAPPING, REQUIRED, P, Params, Ports

from .map_model import MapModel, MapObject
from .perception import ingest_fused
from .sharing import CHUNK, decode_object, encode_object

MAX_RECOGNIZED = 1000
"""Objects one recognition result may carry."""


def _area_names(text: str) -> list[str]:
    return [name for name in text.replace(",", " ").split() if name]


def _holding(model: MapModel, objects: list[MapObject]) -> MapModel:
    """A map like ``model`` (bounds, areas, avoided areas, semantics) holding only ``objects``."""
    made = MapModel(model.bounds, height=model.height, avoided=model.avoided, areas=model.areas,
                    semantics=model.semantics, name=model.name)
    made.add_many(objects)
    return made


class EnvironmentMap(ProcessingPlugin):
    """``plugin.environment-map``: one robot's map, fed by its recognition and completed by its peers' maps."""

    PORTS = Ports(inputs={"*": MAPPING}, outputs={"objects": MAPPING})
    PROVIDES = "map-sharing"  # docs/interfaces.md
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("environment", REQUIRED, "XML file holding the system's <Environment> (the map), relative to the "
          "configuration file.", type=str, file=ENVIRONMENT_FILE),
        P("areas", "", "Areas of the Environment this map holds, separated by spaces or commas (empty: all of it)."),
        P("robot", "", "Source name of this map's own updates (empty: the Smart Resource's name)."),
        P("gate", 0.3, "A recognised shape updates the nearest map object of that tag within this distance.",
          unit="m", above=0.0),
        P("minReliability", 0.0, "Recognised objects less reliable than this are ignored.", min=0.0, max=1.0),
        P("fullEvery", 10, "Every this many frames the output also carries a slice of all the objects.", min=1),
        P("chunk", CHUNK, "Most objects in one output message.", min=1, max=CHUNK),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        base = config_dir(record)
        self.environment_file = base / self.params["environment"]
        self.area_names = _area_names(self.params["areas"])
        self.model: MapModel | None = None
        self.region: Any = None  # the prepared union of the areas (None: the whole map)
        self.robot = self.params["robot"]
        self.frames = 0
        self.applied = 0
        self.rejected = 0
        self._sent: dict[str, tuple[float, str]] = {}
        self._cursor = 0
        self._last_recognized: dict[str, str] = {}  # input → digest of the last result taken (D153)

    # ------------------------------------------------------------------ set-up

    def setup(self) -> None:
        """Read the Environment and keep the objects of the chosen areas."""
        if self.model is not None:
            return
        model = MapModel.from_environment(environment_of(self.environment_file, self.owner))
        unknown = [name for name in self.area_names if name not in model.areas]
        if unknown:
            known = ", ".join(sorted(model.areas)) or "none"
            raise ValueError(f"{self.owner}: parameter 'areas' names {', '.join(map(repr, unknown))}, not Areas of "
                             f"environment {model.name!r} ({known})")
        if self.area_names:
            self.region = prep(shapely.union_all([model.areas[name] for name in self.area_names]))
            model = _holding(model, [o for o in model.objects.values() if self.holds(o.x, o.y)])
        self.model = model

    def holds(self, x: float, y: float) -> bool:
        """Does this map cover the point (in one of its areas, or anywhere when it has none)?"""
        return self.region is None or bool(self.region.covers(shapely.Point(x, y)))

    # ------------------------------------------------------------------ frames

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """Take the fresh inputs (recognition results, peers' updates), publish this map's changes."""
        if self.model is None:
            self.setup()
        assert self.model is not None
        if not self.robot:
            self.robot = context.resource or self.record.name
        if not isinstance(data, Mapping):
            raise ValueError(f"{self.owner}: an input is not a mapping but {type(data).__name__}")
        messages = {"input": data} if isinstance(data.get("objects"), list | tuple) else dict(data)
        applied = 0
        for name, message in messages.items():
            if message is None:
                continue
            if not isinstance(message, Mapping) or not isinstance(message.get("objects"), list | tuple):
                raise ValueError(f"{self.owner}: input {name!r} is neither a recognition result nor a map update "
                                 "(no 'objects' list)")
            if message.get("type") == "objects":
                applied += self.apply(message["objects"])
            else:
                applied += self._recognized(str(name), message, context.stamp)
        self.applied = applied
        update = self._update(full=self.frames % self.params["fullEvery"] == 0)
        self.frames += 1
        return {"type": "objects", "map": self.robot, "stamp": context.stamp, "objects": update,
                "map_objects": float(len(self.model)), "applied": float(applied), "rejected": float(self.rejected)}

    def apply(self, items: Any) -> int:
        """Apply a peer's encoded objects (newer time mark wins); how many changed the map."""
        assert self.model is not None
        applied = 0
        items = list(items)
        if len(items) > CHUNK:  # no peer sends more: refused whole, as MapShare does
            self.rejected += len(items)
            return 0
        for item in items:
            try:
                obj = decode_object(item)
            except ValueError:
                self.rejected += 1
                continue
            held = obj.name in self.model or self.holds(obj.x, obj.y)  # a held object may leave the areas
            if held and self.model.replace(obj):
                applied += 1
                self._sent[obj.name] = (obj.stamp, obj.source)  # the sender has it: no echo
        return applied

    def _recognized(self, name: str, message: Mapping[str, Any], stamp: float) -> int:
        """Enter a recognition result (once: the stream hands the newest value of every input each frame)."""
        assert self.model is not None
        digest = hashlib.sha1(msgpack.packb(codec.encode(dict(message)), use_bin_type=True)).hexdigest()
        if self._last_recognized.get(name) == digest:
            return 0
        self._last_recognized[name] = digest
        own = message.get("stamp", stamp)
        if isinstance(own, bool) or not isinstance(own, int | float) or not math.isfinite(own):
            raise ValueError(f"{self.owner}: input {name!r} field 'stamp' = {own!r} is not a time")
        kept = []
        for index, item in enumerate(message["objects"][:MAX_RECOGNIZED]):
            where = f"{self.owner}: input {name!r} objects[{index}]"
            if not isinstance(item, Mapping) or not isinstance(item.get("name"), str) or not item["name"]:
                raise ValueError(f"{where} has no 'name'")
            if item.get("x") is None:
                continue  # a lone 2D ray: no position to put in the map
            values = [item.get("x"), item.get("y"), item.get("z") or 0.0, item.get("reliability", 1.0)]
            if not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in values):
                raise ValueError(f"{where}: x, y, z and reliability must be finite numbers, got {values}")
            if not 0.0 <= float(values[3]) <= 1.0:
                raise ValueError(f"{where} field 'reliability' = {values[3]} is not in [0, 1]")
            if float(values[3]) >= self.params["minReliability"] and self.holds(float(values[0]), float(values[1])):
                kept.append(item)
        outcomes = ingest_fused(self.model, {"objects": kept}, stamp=float(own), gate=self.params["gate"],
                                source=self.robot, suffix=f"@{self.robot}")
        return sum(outcome in ("added", "moved", "confirmed") for _, outcome in outcomes)

    def _update(self, *, full: bool) -> list[dict[str, Any]]:
        """The encoded objects of this frame's update: changed ones first, then (``full``) a slice of all."""
        assert self.model is not None
        chunk = self.params["chunk"]
        objects = list(self.model.objects.values())
        batch = [o for o in objects if self._sent.get(o.name) != (o.stamp, o.source)][:chunk]
        if full and objects and len(batch) < chunk:
            start = self._cursor % len(objects)
            taken = {o.name for o in batch}
            rotation = [o for o in objects[start:] + objects[:start] if o.name not in taken][: chunk - len(batch)]
            self._cursor = start + len(rotation)
            batch += rotation
        self._sent.update((o.name, (o.stamp, o.source)) for o in batch)
        return [encode_object(o) for o in batch]

    def objects(self) -> list[MapObject]:
        """The objects this map holds."""
        return [] if self.model is None else list(self.model.objects.values())

    # ------------------------------------------------------------------ delegation

    def state(self) -> dict[str, Any]:
        """The objects (encoded), what was sent and the counters: a copy elsewhere goes on from here."""
        if self.model is None:
            return {}
        return {"kind": "environment-map", "robot": self.robot, "frames": self.frames, "cursor": self._cursor,
                "rejected": self.rejected, "objects": [encode_object(o) for o in self.model.objects.values()],
                "sent": {name: list(mark) for name, mark in self._sent.items()},
                "recognized": dict(self._last_recognized)}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Go on from :meth:`state` (after ``setup()``); ValueError naming what is wrong."""
        if not state:
            return
        if self.model is None:
            self.setup()
        assert self.model is not None
        try:
            if state.get("kind") != "environment-map":
                raise ValueError(f"kind is {state.get('kind')!r}")
            objects = [decode_object(item) for item in state["objects"]]
            self.robot, self.frames = str(state["robot"]), int(state["frames"])
            self._cursor, self.rejected = int(state["cursor"]), int(state["rejected"])
            self._sent = {str(k): (float(v[0]), str(v[1])) for k, v in state["sent"].items()}
            self._last_recognized = {str(k): str(v) for k, v in state["recognized"].items()}
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
            raise ValueError(f"{self.owner}: not an environment-map state ({exc})") from None
        self.model = _holding(self.model, objects)
