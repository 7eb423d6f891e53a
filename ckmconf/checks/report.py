"""Collecting semantic problems with precise locations, and wording common ones alike (§3.1.5.2)."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

from ..binding import Record
from ..errors import ConfigError, Loc, located
from ..source import SourceFile


class Reporter:
    """Turns (record, attribute, message) into located ConfigErrors."""

    def __init__(self, sources: dict[str, SourceFile] | None = None) -> None:
        self.sources = sources or {}
        self.errors: list[ConfigError] = []

    def error(self, record: Record, message: str, attr: str | None = None, offset: int | None = None) -> None:
        """Report at the record, or at one of its attributes (``offset``: a character of its value)."""
        loc = located(record)
        if attr is not None:
            source = self.sources.get(loc.file)
            if source is None:
                loc = Loc(loc.file, loc.line, loc.column, f"{loc.xpath}/@{attr}")
            elif offset is None:
                loc = source.attr_loc_at(loc, attr)
            else:
                loc = source.value_loc_at(loc, attr, offset)
        self.errors.append(ConfigError.at(loc, message))

    def unique(self, records: Iterable[Record], kind: str, where: str, key: str = "name") -> None:
        """Report every record whose ``key`` repeats an earlier one's."""
        first: dict[str, Record] = {}
        for record in records:
            value = getattr(record, key)
            if value in first:
                earlier = first[value].loc
                at = (
                    f" (first at line {earlier.line})"
                    if earlier and record.loc and earlier.file == record.loc.file
                    else (f" (first at {earlier.file}:{earlier.line})" if earlier else "")
                )
                self.error(record, f"duplicate {kind} {value!r} in {where}{at}", key)
            else:
                first[value] = record


def missing(kind: str, name: str, where: str, candidates: Iterable[str]) -> str:
    """ "<kind> 'x' does not exist in <where>", with a suggestion or the list of what does."""
    names = sorted(set(candidates))
    close = difflib.get_close_matches(name, names, n=1, cutoff=0.6)
    if not close and "/" in "".join(names):
        # Topics: "wheel_odom" should find "/kobuki/wheel_odom".
        tails = {n.rsplit("/", 1)[-1]: n for n in names}
        near = difflib.get_close_matches(name.rsplit("/", 1)[-1], list(tails), n=1, cutoff=0.6)
        close = [tails[near[0]]] if near else []
    if close:
        return f"{kind} {name!r} does not exist in {where}; did you mean {close[0]!r}?"
    if not names:
        return f"{kind} {name!r} does not exist in {where} (none is defined)"
    shown = ", ".join(names[:12]) + (", …" if len(names) > 12 else "")
    return f"{kind} {name!r} does not exist in {where} (defined: {shown})"
