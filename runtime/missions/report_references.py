"""Reference tables the run report shows beside a run's own Table 7.9 rows (§7.5.2; D272).

A system's designers may have published figures for its missions: the thesis' Table 7.9 for its
lab, a previous release's measurements for a product. A :class:`ReferenceTable` holds such rows;
each row names, per visit, the ``fnmatch`` patterns of the leaf-row labels
(:attr:`~.report.StateRow.label`) it stands for, because a published row may group states
differently from the mission (two states joined, a state visited twice). A row with no matching
state in an agent is left out for that agent, so a table about another system shows nothing.

Tables come from installed packages through the entry-point group ``ckm.report_references``,
each entry naming a :class:`ReferenceTable` object (the lab's package registers the thesis'
Table 7.9 there); the toolkit itself ships none.
"""

from __future__ import annotations

from dataclasses import dataclass
from fnmatch import fnmatchcase
from importlib.metadata import entry_points

from .report import AgentReport, StateRow

GROUP = "ckm.report_references"
"""The entry-point group of reference tables."""


@dataclass(frozen=True)
class ReferenceRow:
    """One published row, and the patterns of the run's leaf-row labels per visit it compares with."""

    state: str
    times: tuple[float, ...]  # seconds, one per visit
    contributions: tuple[float, ...]  # fractions, one per visit
    performance: float
    visits: tuple[tuple[str, ...], ...]  # per visit, the label patterns of the run's rows


@dataclass(frozen=True)
class ReferenceTable:
    """Published rows and where they were published (the report says "Next to SOURCE")."""

    source: str
    rows: tuple[ReferenceRow, ...]


@dataclass(frozen=True)
class Comparison:
    """A reference row next to what the run measured for the states it stands for."""

    reference: ReferenceRow
    times: tuple[float, ...]  # per visit group of the reference row
    contributions: tuple[float, ...]
    performance: float | None
    rows: tuple[str, ...]  # the labels of the run's rows that matched


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


def compare(table: ReferenceTable, agent: AgentReport) -> list[Comparison]:
    """The rows of ``table`` that have states in ``agent``'s (leaf-depth) report, with the run's figures."""
    found = []
    for reference in table.rows:
        groups = [[r for r in agent.rows if _matches(r, patterns)] for patterns in reference.visits]
        matched = [r for group in groups for r in group]
        if not matched:
            continue
        groups = [group for group in groups if group]  # a visit the run never made is left out, not 0 s
        times = tuple(sum(r.time for r in group) for group in groups)
        contributions = tuple(sum(sum(r.contribution) for r in group) for group in groups)
        found.append(Comparison(reference, times, contributions, _weighted(matched), tuple(r.label for r in matched)))
    return found


def installed_tables() -> tuple[list[ReferenceTable], list[str]]:
    """The reference tables installed packages register, and one problem line per entry that fails.

    A table is an addition to the report: one that cannot be loaded is said, not fatal.
    """
    tables: list[ReferenceTable] = []
    problems: list[str] = []
    for point in sorted(entry_points(group=GROUP), key=lambda p: p.name):
        try:
            table = point.load()
        except Exception as exc:  # an add-on's import error must not cost the run its report
            problems.append(f"reference table {point.name!r} ({point.value}) not loaded: {exc}")
            continue
        if not isinstance(table, ReferenceTable):
            problems.append(f"reference table {point.name!r} ({point.value}) is a {type(table).__name__}, "
                            "not a ReferenceTable")
            continue
        tables.append(table)
    return tables, problems
