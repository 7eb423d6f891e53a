"""Records that carry a condition: ``<Transition when=…>`` (missions.xsd) and ``<Switch when=…>`` (kernel.xsd).

The condition language is :mod:`ckmconf.expressions`. A record parses its ``when`` once, when it
is built (at load, by :func:`ckmconf.binding.bind`), and every consumer (the semantic checks, the
kernel's controller switching, the HFSM, the static mission validation) uses that one parsed
:class:`~ckmconf.expressions.Condition`. A condition that does not parse is kept as its error: the
checks report it at load as ``FILE:LINE:COL`` of the character at fault, and reading
:attr:`ConditionRecord.condition` raises it as a located :class:`~ckmconf.errors.ConfigError`.
"""

from __future__ import annotations

from typing import ClassVar

from ..binding import Record
from ..errors import ConfigError
from ..expressions import Condition, ExpressionError, Vocabulary, parse


class ConditionRecord(Record):
    """Base of a record whose ``when`` attribute is a condition of the class's ``VOCABULARY``."""

    VOCABULARY: ClassVar[Vocabulary]
    when: str  # each subclass declares it as its XML attribute
    _parsed: Condition | ExpressionError

    def __post_init__(self) -> None:
        try:
            parsed: Condition | ExpressionError = parse(str(self.when), self.VOCABULARY)
        except ExpressionError as exc:
            parsed = exc
        object.__setattr__(self, "_parsed", parsed)  # frozen: set once, here

    @property
    def condition(self) -> Condition:
        """The parsed condition; a ConfigError at ``@when`` if it does not parse."""
        if isinstance(self._parsed, ExpressionError):
            raise ConfigError.of(self, str(self._parsed), "when")
        return self._parsed

    @property
    def condition_error(self) -> ExpressionError | None:
        """Why the condition does not parse (its ``column`` is the character at fault), or None."""
        return self._parsed if isinstance(self._parsed, ExpressionError) else None


__all__ = ["ConditionRecord"]
