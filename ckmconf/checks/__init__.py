"""Semantic checks (§3.1.5.2): cross-references, uniqueness, shapes and orderings the XSD cannot express."""

from __future__ import annotations

import dataclasses

from ..binding import Record
from ..model import System
from ..model.params import Param
from .environment import check_environment
from .kernel import check_kernel
from .missions import check_missions
from .report import Reporter
from .resources import check_resources
from .scope import Scope


def check_system(system: System, report: Reporter) -> None:
    """Run every semantic check on a merged system; problems go to ``report``."""
    scope = Scope.of(system)
    check_kernel(system, scope, report)
    check_resources(system, scope, report)
    check_missions(system, scope, report)
    check_environment(system, report)
    _check_params(system, report, set())


def _check_params(record: Record, report: Reporter, seen: set[int]) -> None:
    """A ``<Param>`` given twice in one element is an error at the second (else the last would silently win)."""
    if id(record) in seen:
        return
    seen.add(id(record))
    for field in dataclasses.fields(record):
        value = getattr(record, field.name)
        items = value if isinstance(value, tuple) else (value,)
        if field.name == "params" and items and all(isinstance(p, Param) for p in items):
            name = getattr(record, "name", None)
            report.unique(items, "Param", f"{record.TAG} {name!r}" if isinstance(name, str) else record.TAG)
        for item in items:
            if isinstance(item, Record):
                _check_params(item, report, seen)


__all__ = ["Reporter", "check_system"]
