"""What a perception service a behavior watches can report, read from the configuration alone (D302).

A detector kind may say, as class attributes of its plugin class:

- ``POSITIONS = "image"``: its objects' ``x``, ``y`` are shares of the image frame, no metric
  position (``colour-detection``, ``orb-recognition``, ``keypoint-matching``): a behavior that places
  sightings on the map refuses it, and names the kind that turns them into map positions;
- ``labels(record)`` (a classmethod): the labels it can report given its ``<Plugin>`` record (the
  colour names of ``colour-detection``), None when only its model knows;
- ``PASSES = "objects"``: it keeps the labels of the objects it receives on that Input
  (``ground-projection``): what it can report is what the service publishing that topic can.

:func:`perception_reports` follows a service through such pass-through kinds to its detector.
"""

from __future__ import annotations

from dataclasses import dataclass

from ckmconf.model import System
from runtime.registry import RegistryError, default_registry


@dataclass(frozen=True)
class Reports:
    """What a perception service can report: the detector kind it comes from, whether its positions are
    image shares, and its labels (None: not known from the configuration)."""

    kind: str
    image: bool
    labels: frozenset[str] | None


def perception_reports(system: System, ref: str, depth: int = 0) -> Reports | None:
    """What the service ``ref`` ("Resource.Service") reports; None when the configuration does not say."""
    found = system.service(ref)
    if found is None or depth > 8:
        return None
    resource, service = found
    plugins = {p.name: p for p in resource.plugins}
    profiles = {p.name: p for p in resource.profiles}
    kinds = {profiles[s.profile].output_plugin() for s in service.scenarios if s.profile in profiles}
    if len(kinds) != 1 or (record := plugins.get(kinds.pop())) is None:
        return None
    try:
        cls = default_registry().find("plugin", record.kind)
    except RegistryError:
        return None
    if cls is None:
        return None
    passes = getattr(cls, "PASSES", None)
    if isinstance(passes, str):
        topic = next((i.topic for i in service.inputs if i.name == passes), None)
        producers = [f"{r.name}.{s.name}" for r in system.resources for s in r.services
                     if any(o.topic == topic for o in s.outputs)]
        upstream = perception_reports(system, producers[0], depth + 1) if len(producers) == 1 else None
        return None if upstream is None else Reports(upstream.kind, False, upstream.labels)
    labels = getattr(cls, "labels", None)
    known = labels(record) if callable(labels) else None
    return Reports(record.kind, getattr(cls, "POSITIONS", None) == "image",
                   frozenset(known) if known is not None else None)
