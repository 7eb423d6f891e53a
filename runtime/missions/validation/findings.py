"""What the off-line validation reports: one located finding per problem (§5.4)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Literal

from ckmconf.binding import Record

Severity = Literal["error", "warning"]


@dataclass(frozen=True)
class Finding:
    """One problem of a mission found by the validation mechanism (§5.4), located at the record that causes it.

    ``kind`` is a stable identifier (``unreachable-state``, ``shadowed-transition`` …) that tests
    and tools match on; ``message`` says what is wrong and how to fix it, naming the mission,
    state or transition. ``transition`` is written ``"FROM -> TO"``.
    """

    kind: str
    severity: Severity
    message: str
    mission: str
    state: str | None = None
    transition: str | None = None
    file: str = "<memory>"
    line: int = 0
    column: int = 0
    xpath: str = ""

    def format(self) -> str:
        """``FILE:LINE:COL: XPATH: [kind] message``, the style of ``ckm-validate``."""
        return f"{self.file}:{self.line}:{self.column}: {self.xpath}: [{self.kind}] {self.message}"

    def to_json(self) -> dict[str, object]:
        """All fields as a JSON-ready dict (the ``--json`` output of ``ckm-mission validate``)."""
        return asdict(self)

    def sort_key(self) -> tuple[str, int, int, str, str]:
        """Order of reporting: by file, line, column, then kind and message."""
        return (self.file, self.line, self.column, self.kind, self.message)


def finding(
    kind: str,
    severity: Severity,
    message: str,
    record: Record | None,
    *,
    mission: str,
    state: str | None = None,
    transition: str | None = None,
) -> Finding:
    """A finding located at ``record`` (records built in memory have no location)."""
    loc = record.loc if record is not None else None
    if loc is None:
        xpath = f"/{record.TAG}" if record is not None and record.TAG else ""
        return Finding(kind, severity, message, mission, state, transition, xpath=xpath)
    return Finding(kind, severity, message, mission, state, transition, loc.file, loc.line, loc.column, loc.xpath)


def arrow(source: str, target: str) -> str:
    """How a transition is named in findings."""
    return f"{source} -> {target}"


def ordered(findings: list[Finding]) -> list[Finding]:
    """Without repeats, errors and warnings together, by file position."""
    return sorted(dict.fromkeys(findings), key=Finding.sort_key)
