"""The thesis' Table 7.9 (§7.5.2, p. 132) and its match with a run's rows, for the HTML report.

Table 7.9 characterises the cooperative mission of Fig. 7.13 by behavior: execution time,
contribution to the mission (a fraction, though the header says %) and average performance. Its
rows group states differently from our missions (configs/usecase/missions.xml): NAVIGATION has two
visits, going to the workbench and coming back home, which are our ``Navigation`` sub-mission and
the ``NAV``/``WAIT`` states of ``ObjectPlace``; APPR-PICK and PLACE-BACK join two of our states;
SPOT_TRACK and SPOT_FIX are the Nao's OBJ_TRACK and OBJ_FIX. Each thesis row therefore names, per
visit, the ``fnmatch`` patterns of our leaf rows' labels (:attr:`~.report.StateRow.label`) it
stands for; a row with no matching state in an agent is left out for that agent.
"""

from __future__ import annotations

from dataclasses import dataclass
from fnmatch import fnmatchcase

from .report import AgentReport, StateRow


@dataclass(frozen=True)
class ThesisRow:
    """One row of Table 7.9, and the patterns of our leaf-row labels per visit it compares with."""

    state: str
    times: tuple[float, ...]  # seconds, one per visit
    contributions: tuple[float, ...]  # fractions, one per visit
    performance: float
    visits: tuple[tuple[str, ...], ...]  # per visit, the label patterns of our rows


TABLE_7_9: tuple[ThesisRow, ...] = (
    ThesisRow(
        "NAVIGATION", (56.676, 52.856), (0.29, 0.27), 0.89, (("Navigation/*",), ("ObjectPlace/NAV", "ObjectPlace/WAIT"))
    ),
    ThesisRow("SPOT", (18.651,), (0.096,), 0.74, (("*SPOT",),)),
    ThesisRow("APPR-PICK", (58.713,), (0.30,), 0.93, (("*APPR", "*PICK"),)),
    ThesisRow("PLACE-BACK", (26.121,), (0.13,), 0.95, (("*PLACE", "*BACK"),)),
    ThesisRow("SPOT_TRACK", (23.57,), (0.24,), 1.0, (("*OBJ_TRACK",),)),
    ThesisRow("SPOT_FIX", (75.327,), (0.76,), 0.62, (("*OBJ_FIX",),)),
)
"""Table 7.9 of the thesis (p. 132): Agent 1's rows, then Agent 2's."""

TABLE_SOURCE = "thesis Table 7.9 (§7.5.2, p. 132)"


@dataclass(frozen=True)
class Comparison:
    """A thesis row next to what the run measured for the states it stands for."""

    thesis: ThesisRow
    times: tuple[float, ...]  # per visit group of the thesis row
    contributions: tuple[float, ...]
    performance: float | None
    rows: tuple[str, ...]  # the labels of our rows that matched


def _matches(row: StateRow, patterns: tuple[str, ...]) -> bool:
    return any(fnmatchcase(row.label, p) for p in patterns)


def _weighted(rows: list[StateRow]) -> float | None:
    """The time-weighted mean performance of ``rows`` (their plain mean when no time was spent)."""
    rated = [r for r in rows if r.performance is not None]
    total = sum(r.time for r in rated)
    if not rated:
        return None
    if total <= 0:
        return sum(r.performance or 0.0 for r in rated) / len(rated)
    return sum((r.performance or 0.0) * r.time for r in rated) / total


def compare(agent: AgentReport) -> list[Comparison]:
    """The thesis rows that have states in ``agent``'s (leaf-depth) report, with our figures."""
    found = []
    for thesis in TABLE_7_9:
        groups = [[r for r in agent.rows if _matches(r, patterns)] for patterns in thesis.visits]
        matched = [r for group in groups for r in group]
        if not matched:
            continue
        groups = [group for group in groups if group]  # a visit the run never made is left out, not 0 s
        times = tuple(sum(r.time for r in group) for group in groups)
        contributions = tuple(sum(sum(r.contribution) for r in group) for group in groups)
        found.append(Comparison(thesis, times, contributions, _weighted(matched), tuple(r.label for r in matched)))
    return found
