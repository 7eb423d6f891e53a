"""The plugin registry: kind names in configurations → classes (BehaviorTree.CPP's factory).

Plugins register through the entry-point group ``ckm.plugins`` with names ``CATEGORY.KIND``
(``hardware.loopback``, ``controller.pid``, ``function.scale``…), or by ``register()`` in code.
Registering a name twice is an error; an unknown name is a ConfigError at the element that
asked for it, listing what is registered. Classes are imported only when first needed.
"""

from __future__ import annotations

import importlib
from collections.abc import Collection
from importlib.metadata import entry_points
from typing import Any

from ckmconf.binding import Record
from ckmconf.checks.report import missing
from ckmconf.errors import MEMORY_FILE, ConfigError

GROUP = "ckm.plugins"
CATEGORIES = ("hardware", "controller", "function", "plugin", "behavior")
NOUNS = {
    "hardware": "hardware backend",
    "controller": "controller kind",
    "function": "function",
    "plugin": "processing plugin",
    "behavior": "behavior kind",
}
"""How messages name a kind of each category."""


class RegistryError(RuntimeError):
    """A programming error in plugin registration (not a configuration problem)."""


class Registry:
    """Maps (category, kind) to a class, loaded lazily from entry points."""

    def __init__(self, *, load_entry_points: bool = True, packages: Collection[str] | None = None) -> None:
        """``packages``: load only the entry points of these distributions (None: of every one)."""
        self._targets: dict[tuple[str, str], str | type[Any]] = {}
        self._origins: dict[tuple[str, str], str] = {}
        if load_entry_points:
            for point in entry_points(group=GROUP):
                origin = point.dist.name if point.dist is not None else ""
                if packages is not None and origin not in packages:
                    continue
                category, _, kind = point.name.partition(".")
                self._add(category, kind, point.value)
                self._origins[(category, kind)] = origin

    def register(self, category: str, kind: str, cls: type[Any] | str) -> None:
        """Register a class, or its ``module:Class`` path (imported when first needed)."""
        self._add(category, kind, cls)

    def _add(self, category: str, kind: str, target: str | type[Any]) -> None:
        if category not in CATEGORIES or not kind:
            raise RegistryError(f"plugin name {category}.{kind!r} must be CATEGORY.KIND with CATEGORY in {CATEGORIES}")
        key = (category, kind)
        if key in self._targets and self._targets[key] != target:
            raise RegistryError(f"{category} {kind!r} is registered twice ({self._targets[key]!r} and {target!r})")
        self._targets[key] = target

    def kinds(self, category: str) -> list[str]:
        """The kind names registered in ``category`` (values a ``kind=`` attribute may take), sorted."""
        return sorted(kind for cat, kind in self._targets if cat == category)

    def missing(self, category: str, kind: str) -> str:
        """The message for a kind nobody registered, with a suggestion or the list of those that are."""
        return missing(NOUNS.get(category, category), kind, "the registry", self.kinds(category))

    def names(self) -> list[tuple[str, str]]:
        """Every registered (category, kind), sorted."""
        return sorted(self._targets)

    def target(self, category: str, kind: str) -> str:
        """Where a kind comes from: ``module:Class`` (for listings; nothing is imported)."""
        target = self._targets[(category, kind)]
        return target if isinstance(target, str) else f"{target.__module__}:{target.__qualname__}"

    def origin(self, category: str, kind: str) -> str:
        """The distribution whose entry point registered a kind ("" for ``register()`` in code)."""
        return self._origins.get((category, kind), "")

    def find(self, category: str, kind: str) -> type[Any] | None:
        """The class registered for ``kind`` (imported, never instantiated), or None if there is none.

        Raises:
            RegistryError: the entry point names a module or class that cannot be imported.
        """
        if (category, kind) not in self._targets:
            return None
        try:
            return self.resolve(category, kind)
        except (ImportError, AttributeError) as exc:
            where = self.target(category, kind)
            raise RegistryError(f"{category} {kind!r} ({where}) cannot be imported: {exc}") from exc

    def resolve(self, category: str, kind: str, record: Record | None = None, attr: str = "kind") -> type[Any]:
        """The class registered for ``kind``, or a ConfigError located at ``record``."""
        target = self._targets.get((category, kind))
        if target is None:
            message = self.missing(category, kind)
            if record is None:
                raise ConfigError(MEMORY_FILE, 1, 1, f"/@{attr}", message)
            raise ConfigError.of(record, message, attr)
        if isinstance(target, str):
            module, _, name = target.partition(":")
            target = getattr(importlib.import_module(module), name)
            assert isinstance(target, type)
            self._targets[(category, kind)] = target
        return target


_DEFAULT: Registry | None = None


def default_registry() -> Registry:
    """The process-wide registry built from the installed entry points."""
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = Registry()
    return _DEFAULT
