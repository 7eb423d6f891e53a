"""The static off-line validation of a whole system (§5.4, §7.5.1), the entry point tools import.

``check_missions`` and ``check_plans`` find, with no simulation, what the configuration alone
shows: the static checks of every top mission's HFSM (:mod:`.static`), SRFlowGen's trace of its
quality requirements (:mod:`.srflowgen`) and each plan's wait-for graph (:mod:`.plans`). The
editor runs them on every change; ``ckm-mission validate`` adds the simulated runs of
:mod:`runtime.missions.fake`. Like the modules it calls, it needs nothing but the configuration
records (and networkx).
"""

from __future__ import annotations

from ckmconf.model import System

from .findings import Finding
from .plans import check_plans
from .srflowgen import srflowgen
from .static import check_mission, nesting_graph


def top_missions(system: System) -> list[str]:
    """Missions no state nests (``<State mission=…>``): the ones an agent runs, and the ones to
    validate when none is named."""
    graph = nesting_graph(system)
    return [m.name for m in system.missions if graph.in_degree(m.name) == 0]


def check_missions(system: System) -> list[Finding]:
    """The static findings of every top mission of ``system``, nested missions included.

    Args:
        system: a loaded system (``ckmconf.load``; a lax load is fine as long as it gave a system).

    Returns:
        For each top mission in document order, its static findings (:func:`.static.check_mission`)
        then SRFlowGen's (:func:`.srflowgen.srflowgen` with the system's ``<Validation>`` or the
        defaults). The plans' findings are :func:`check_plans`'.
    """
    found: list[Finding] = []
    for mission in top_missions(system):
        found += check_mission(system, mission)
        found += srflowgen(system, mission, system.validation)[0]
    return found


__all__ = ["Finding", "check_missions", "check_plans", "top_missions"]
