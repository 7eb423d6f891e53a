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
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

from ckmconf.model.missions import CompositionMatrix, Require

from ..resources.quality import probability_within


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
