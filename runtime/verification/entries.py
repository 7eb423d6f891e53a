"""Per-name Param values, ``"name: v1 v2; name: v…"``, declared and checked like any other Param (D184).

Some kinds take one value per input or per object in a single ``<Param>``: the feature fusion's
``inputs="rgb: line; depth: point"``, ``poses``, ``mounts``, ``bases``, ``sigmas``, ``cameras``,
``objects``; the pan-tilt tracker's ``heights``. A kind declares such a Param with
``P(..., entries=Entries(...))``: what each entry holds (words or finite numbers, how many, the
accepted words, a lower bound) and, with ``of``, the Param whose entry names its names must be.
:func:`~runtime.verification.manifest.read_params` then hands the kind the parsed value, a dict
``{name: (values…)}``, and ``verify`` (hence ``ckm-validate``) reports a bad entry at
``FILE:LINE:COL`` of the entry itself: the same parser, before anything is built.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any


class ParamError(ValueError):
    """A Param a kind cannot use: unknown, missing, of the wrong type or out of range.

    ``offset`` is the character of the Param's value where the problem is, when it is one entry
    of a per-name value (the verifier places the error there); None for the value as a whole.
    """

    def __init__(self, message: str, offset: int | None = None) -> None:
        super().__init__(message)
        self.offset = offset


Parsed = dict[str, tuple[Any, ...]]
"""A per-name value as the kind receives it: entry name → its values (words or floats)."""


@dataclass(frozen=True)
class Entries:
    """The syntax of a per-name Param value, ``"name: v1 v2; name: v…"``.

    Args:
        form: each entry's values as the reference shows them (``"x y z roll pitch yaw"``).
        count: how many values an entry has (at least, with ``most``).
        most: the most values an entry may have (None: exactly ``count``).
        numbers: the values are finite numbers (floats), else words.
        choices: the accepted words (one value each).
        above: every number must be greater than this.
        of: the Param whose entry names this one's names must be (``"inputs"``).
        of_value: what those entries of ``of`` must hold (``"line"``: only line inputs have cameras).
        noun: what ``of``'s entries are, with its article, for messages (``"an input"``).
        need: what an entry of words needs, for messages (default: ``form``).
    """

    form: str
    count: int = 1
    most: int | None = None
    numbers: bool = False
    choices: tuple[str, ...] = ()
    above: float | None = None
    of: str | None = None
    of_value: str | None = None
    noun: str = "an entry"
    need: str = ""

    def syntax(self) -> str:
        """The value's syntax as the reference shows it: ``'name: line|point; …'``."""
        return f"'name: {'|'.join(self.choices) if self.choices else self.form}; …'"

    def parse(self, text: str, param: str) -> Parsed:
        """``text`` as {name: values}, or a ParamError at the offending entry's offset."""
        found: Parsed = {}
        for start, entry in _split(text):
            name, colon, values = entry.partition(":")
            if not colon or not name.strip() or name.strip() in found:
                raise ParamError(f"parameter {param!r} entry {entry!r} is not 'name: values' with a new name", start)
            found[name.strip()] = self._values(values.split(), param, name.strip(), start)
        return found

    def _values(self, words: list[str], param: str, name: str, start: int) -> tuple[Any, ...]:
        where = f"parameter {param!r} for {name!r}"
        most = self.count if self.most is None else self.most
        if self.choices:
            if len(words) != 1 or words[0] not in self.choices:
                accepted = " or ".join(", ".join(repr(c) for c in self.choices).rsplit(", ", 1))
                raise ParamError(f"{where} must be {accepted}, got {words}", start)
            return tuple(words)
        if not self.numbers:
            if not self.count <= len(words) <= most:
                raise ParamError(f"{where} needs {self.need or self.form}", start)
            return tuple(words)
        try:
            values = tuple(float(w) for w in words)
        except ValueError:
            values = ()
        if not self.count <= len(values) <= most or not all(math.isfinite(v) for v in values):
            many = f"{self.count} to {most}" if most != self.count else str(self.count)
            plural = "s" if most != 1 else ""
            raise ParamError(f"{where} needs {many} finite number{plural}, got {words}", start)
        low = next((v for v in values if self.above is not None and not v > self.above), None)
        if low is not None:
            shown = f" = {low}" if len(values) == 1 else f" value {low}"
            raise ParamError(f"{where}{shown} must be greater than {self.above:g}", start)
        return values

    def strays(self, param: str, value: Parsed, text: str | None, values: Mapping[str, Any]) -> Iterator[ParamError]:
        """A ParamError for each entry of ``value`` whose name is not an entry of Param ``of`` (holding ``of_value``).

        Args:
            param: this Param's name.
            value: its parsed value.
            text: its text as given (None when defaulted), to place each error at its entry.
            values: every Param of the element, parsed.
        """
        names = values.get(self.of) if self.of is not None else None
        if not isinstance(names, Mapping):
            return
        starts = {e.partition(":")[0].strip(): s for s, e in _split(text)} if text is not None else {}
        for name in value:
            if name not in names or (self.of_value is not None and tuple(names[name])[:1] != (self.of_value,)):
                yield ParamError(
                    f"parameter {param!r} names {name!r}, not {self.noun} of {self.of!r}", starts.get(name)
                )


def _split(text: str) -> Iterator[tuple[int, str]]:
    """The non-empty ``;``-separated entries of ``text``, stripped, with where each starts."""
    position = 0
    for piece in text.split(";"):
        entry = piece.strip()
        if entry:
            yield position + len(piece) - len(piece.lstrip()), entry
        position += len(piece) + 1


__all__ = ["Entries", "ParamError", "Parsed"]
