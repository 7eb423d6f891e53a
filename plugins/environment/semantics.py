"""The semantic dictionary at run time (thesis §6.1.1.2, §7.4.1).

Each object carries a semantic tag; the dictionary entry of that tag answers "what can I do with
this object, under which conditions" (its affordances, each with a condition in words and
possibly a mission), how it moves (static or mobile, maximum speed, axes) and what it is worth
for localization (landmark, restricted-area, free). Behaviors use :meth:`actions` on the objects
of the zoom map to list the actions available around the robot (§7.4.1: "the set of objects
gathered in each area of interest, and its interaction capabilities, will define the range of
actions that the robot can perform").
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Protocol

from ckmconf.model.environment import Semantic


class Tagged(Protocol):
    """Anything with a name and a semantic tag (a map object)."""

    name: str
    tag: str


@dataclass(frozen=True)
class Action:
    """One thing a robot may do with one object: the affordance and the object it applies to."""

    action: str
    target: str
    tag: str
    condition: str | None
    mission: str | None


class SemanticDictionary:
    """The ``<Semantic>`` entries of an ``<Environment>``, by tag (§6.1.1.2)."""

    def __init__(self, entries: Iterable[Semantic] = ()) -> None:
        self._entries: dict[str, Semantic] = {entry.tag: entry for entry in entries}

    @property
    def tags(self) -> list[str]:
        """The tags of the ``<Semantic>`` entries (environment.xsd), in document order."""
        return list(self._entries)

    def __contains__(self, tag: object) -> bool:
        return tag in self._entries

    def entry(self, tag: str) -> Semantic:
        """The entry of ``tag``; a KeyError names the known tags."""
        try:
            return self._entries[tag]
        except KeyError:
            known = ", ".join(sorted(self._entries)) or "none"
            raise KeyError(f"no semantic tag {tag!r} in the dictionary (tags: {known})") from None

    def affordances(self, tag: str) -> Mapping[str, tuple[str | None, str | None]]:
        """``{action: (condition, mission)}`` of a tag; empty for an unknown tag."""
        entry = self._entries.get(tag)
        if entry is None:
            return {}
        return {a.action: (a.condition, a.mission) for a in entry.affordances}

    def can(self, obj: Tagged, action: str) -> Action | None:
        """The affordance letting a robot ``action`` the object, with its condition, or None."""
        found = self.affordances(obj.tag).get(action)
        if found is None:
            return None
        return Action(action, obj.name, obj.tag, *found)

    def actions(self, objects: Iterable[Tagged]) -> list[Action]:
        """Every action available on ``objects`` (e.g. those of the zoom map), object by object."""
        return [
            Action(action, obj.name, obj.tag, condition, mission)
            for obj in objects
            for action, (condition, mission) in self.affordances(obj.tag).items()
        ]

    def is_mobile(self, tag: str) -> bool:
        """Whether objects of the tag move (``dynamic="mobile"``); unknown tags are treated as mobile."""
        entry = self._entries.get(tag)
        return entry is None or entry.dynamic == "mobile"

    def max_speed(self, tag: str) -> float | None:
        """The tag's maximum speed (m/s), if declared."""
        entry = self._entries.get(tag)
        return None if entry is None else entry.max_speed

    def localization_class(self, tag: str) -> str:
        """``landmark``, ``restricted-area`` or ``free`` (unknown tags are free: they tell nothing)."""
        entry = self._entries.get(tag)
        return "free" if entry is None else entry.landmark

    def is_landmark(self, tag: str) -> bool:
        """Static objects usable by the localization (``landmark="landmark"``)."""
        return self.localization_class(tag) == "landmark"
