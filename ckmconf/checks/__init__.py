"""Semantic checks (§3.1.5.2): cross-references, uniqueness, shapes and orderings the XSD cannot express."""

from __future__ import annotations

from ..model import System
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


__all__ = ["Reporter", "check_system"]
