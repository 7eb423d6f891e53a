"""Service states and the Services Performance Composition of eq. 5.1 (thesis §5.1.2).

Eq. 5.1 as printed multiplies ``sp_i`` by row i of SC, and asks every row and column to sum to 1,
which Table 7.6 — the matrix the thesis uses — does not. We read it (docs/decisions.md D13) as a
weighted mean per service of what it depends on, averaged over the behavior's services::

    P_i = Σ_j sc_ij · sp_j / Σ_j sc_ij          SPC = (1/n) Σ_i P_i   (i over the behavior's services)

``rule="strict"`` matrices sum to 1 per row already, so the normalisation changes nothing there.

Service state ``sp`` (the thesis: "indicates if the service is running or not; whenever it is
running, a performance measure is provided according to the average service qualities"):
0 while the service is not heard from; otherwise the mean, over the behavior's requirements on
it, of ``min(1, P(within bounds) / probability)`` on the measures seen recently — 1 when every
requirement holds, falling smoothly as one is neglected; 1 for a running service the behavior
requires nothing of.

Services of the matrix that the behavior's services depend on but that it does not use itself
(NAV uses AMCL only, yet AMCL's row names Scan and Displacement) are rated from what they
publish (docs/decisions.md D70): 0 while silent; when running, the mean of their recent values
of the measure their ``<Service performance=…>`` names, clamped to [0, 1]; 1 when they name none.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING

from ckmconf.model import System
from ckmconf.model.missions import Behavior, CompositionMatrix, Require

from ..resources.quality import probability_within

if TYPE_CHECKING:
    from .behaviors import ServiceHandle


def service_performance(
    running: bool, requirements: Sequence[Require], samples: Mapping[str, Sequence[float]]
) -> float:
    """``sp`` of one service for one behavior (see the module docstring)."""
    if not running:
        return 0.0
    scores = []
    for requirement in requirements:
        values = samples.get(requirement.measure, ())
        if not values:
            scores.append(0.0)  # running, but not (yet) showing the measure it was asked for
            continue
        met = probability_within(values, requirement.lower, requirement.upper)
        scores.append(min(1.0, met / requirement.probability) if requirement.probability > 0 else 1.0)
    return sum(scores) / len(scores) if scores else 1.0


def composed_performance(
    matrix: CompositionMatrix | None, services: Iterable[str], performance: Mapping[str, float]
) -> float | None:
    """SPC over ``services`` (``Resource.Service`` refs); None when the behavior uses none.

    Without a matrix, or for a service the matrix does not list, a service depends on itself
    only (P_i = sp_i). A service of the matrix the behavior does not use counts with its own
    state in ``performance`` when known, else 0 (it is not running for this behavior).
    """
    used = list(dict.fromkeys(services))
    if not used:
        return None
    index = {ref: k for k, ref in enumerate(matrix.refs())} if matrix is not None else {}
    total = 0.0
    for ref in used:
        row = index.get(ref)
        if matrix is None or row is None:
            total += performance.get(ref, 0.0)
            continue
        weights = matrix.rows[row].values
        norm = sum(weights)
        if norm <= 0:
            total += performance.get(ref, 0.0)
            continue
        total += sum(w * performance.get(other, 0.0) for other, w in zip(matrix.refs(), weights, strict=False)) / norm
    return total / len(used)


def related_services(matrix: CompositionMatrix | None, services: Iterable[str]) -> list[str]:
    """Services of ``matrix`` that a row of ``services`` weighs and that are not among them."""
    if matrix is None:
        return []
    used = list(dict.fromkeys(services))
    refs = matrix.refs()
    related: dict[str, None] = {}
    for ref in used:
        if ref in refs:
            for other, weight in zip(refs, matrix.rows[refs.index(ref)].values, strict=False):
                if weight and other not in used:
                    related[other] = None
    return list(related)


def published_performance(running: bool, samples: Sequence[float]) -> float:
    """``sp`` of a service the behavior does not use: from its published quality (module docstring)."""
    if not running:
        return 0.0
    if not samples:
        return 1.0
    return max(0.0, min(1.0, sum(samples) / len(samples)))


def behavior_performance(
    system: System,
    matrix: CompositionMatrix | None,
    record: Behavior,
    services: Mapping[str, ServiceHandle],
    related: Callable[[str], ServiceHandle | None],
) -> float | None:
    """Eq. 5.1 for one behavior: its services by alias, every other related service by ``related(ref)``."""
    refs: list[str] = []
    states: dict[str, float] = {}
    for uses in record.uses:
        handle = services.get(uses.alias)
        if handle is None:
            continue
        samples = {r.measure: handle.samples(r.measure) for r in uses.requires}
        states[uses.service] = service_performance(handle.running(), uses.requires, samples)
        refs.append(uses.service)
    for ref in related_services(matrix, refs):
        handle = related(ref)
        if handle is None:
            states[ref] = 0.0
            continue
        found = system.service(ref)
        measure = found[1].performance if found is not None else None
        states[ref] = published_performance(handle.running(), handle.samples(measure) if measure else [])
    return composed_performance(matrix, refs, states)
