"""Configuration errors: every problem found in a file, located to the character (§3.1.5.2)."""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Protocol


@dataclass(frozen=True)
class Loc:
    """Where a record came from: file, 1-based line and column, readable element path."""

    file: str
    line: int
    column: int
    xpath: str


MEMORY_FILE = "<memory>"  # the file name of records built in code rather than read from a file


class Located(Protocol):
    """What :meth:`ConfigError.of` needs of a record: where it was read and its element name."""

    @property
    def loc(self) -> Loc | None:
        """Where the record was read (file, line, column, XPath), None if built in memory."""

    @property
    def TAG(self) -> str:  # the records' class constant
        """The record's XML element name."""


def located(record: Located) -> Loc:
    """Where a record was read; a record built in code is placed at ``<memory>:1:1: /TAG``."""
    return record.loc or Loc(MEMORY_FILE, 1, 1, f"/{record.TAG}")


class ConfigError(Exception):
    """One problem in a configuration file (§3.1.5.2: validated before it is distributed).

    Its text is ``FILE:LINE:COL: XPATH: message``; ``ckm-validate`` prints exactly that,
    and the tests compare it verbatim.
    """

    def __init__(self, file: str, line: int, column: int, xpath: str, message: str) -> None:
        super().__init__(f"{file}:{line}:{column}: {xpath}: {message}")
        self.file = file
        self.line = line
        self.column = column
        self.xpath = xpath
        self.message = message

    @classmethod
    def at(cls, loc: Loc, message: str) -> ConfigError:
        """The problem at ``loc``."""
        return cls(loc.file, loc.line, loc.column, loc.xpath, message)

    @classmethod
    def of(cls, record: Located, message: str, attr: str | None = None) -> ConfigError:
        """The problem at a record's element, or at its attribute ``attr`` (``…/@attr``).

        A record built in code has no ``loc``: it is then placed at ``<memory>:1:1: /TAG``.
        """
        loc = located(record)
        xpath = f"{loc.xpath}/@{attr}" if attr else loc.xpath
        return cls(loc.file, loc.line, loc.column, xpath, message)

    def as_dict(self) -> dict[str, object]:
        """The error as JSON-ready fields (``ckm-validate --json``)."""
        return {
            "file": self.file,
            "line": self.line,
            "column": self.column,
            "xpath": self.xpath,
            "message": self.message,
        }

    def sort_key(self) -> tuple[str, int, int, str]:
        """Report order: file, line, column, message."""
        return (self.file, self.line, self.column, self.message)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ConfigError) and self.as_dict() == other.as_dict()

    def __hash__(self) -> int:
        return hash(str(self))

    def __reduce__(self) -> tuple[type[ConfigError], tuple[str, int, int, str, str]]:
        return (ConfigError, (self.file, self.line, self.column, self.xpath, self.message))


class ConfigErrors(Exception):
    """Several problems at once (lax loading collects them; strict loading raises the first)."""

    def __init__(self, errors: Iterable[ConfigError]) -> None:
        self.errors = sorted(set(errors), key=ConfigError.sort_key)
        super().__init__("\n".join(str(e) for e in self.errors))

    def __iter__(self) -> Iterator[ConfigError]:
        return iter(self.errors)

    def __len__(self) -> int:
        return len(self.errors)


def errors_to_json(errors: Iterable[ConfigError]) -> str:
    """The ``--json`` form of ``ckm-validate``: a list of objects."""
    return json.dumps([e.as_dict() for e in errors], indent=2)


__all__ = ["MEMORY_FILE", "ConfigError", "ConfigErrors", "Loc", "Located", "errors_to_json", "located"]
