"""World disturbances as a scenario file (issue K point 3, D178): what a simulated run's world server
does to the laboratory while the missions run — the failures the missions must handle (§7.3–7.5).

One event per line; ``#`` starts a comment. Every event fires once, the first time its trigger
holds (checked after each advance of the physics), in file order::

    EVENT   := TRIGGER ACTION
    TRIGGER := "at" T                                 simulated seconds since the world started
             | "when" COND ("and" COND)*
    COND    := BODY ("within" | "beyond") D "of" PLACE   planar distance, metres
             | "after" T
    PLACE   := BODY | "point" X Y | "start"           a body: the distance to its base's bounding box;
                                                      start: where the measured BODY stood when the
                                                      world was built (any layout's start, D209)
    ACTION  := "move" BODY "to" X Y [Z]               keeps its orientation (and height without Z)
             | "move" BODY "by" DX DY [DZ]
             | "drop" BODY "beside" BODY DX DY        upright on the floor at (DX, DY) in the frame of
                                                      the second body (x ahead): out of a gripper
             | "add" "box" NAME W D H ("at" X Y | "beside" BODY DX DY)   a new box on the floor
             | "remove" BODY                          taken out of the laboratory

BODY names an object of the ``<Environment>``, a robot or a box the scenario adds; the bodies an
event moves must be movable (objects the semantics let a robot ``pick``, added boxes): the world
server's render workers mirror only what can move. A malformed file is a :class:`ScenarioError`
naming FILE:LINE:COL; names are checked against the world when it is built
(:mod:`plugins.sim.disturbances`).

Example (``benchmarks/scenarios/moved-object.scenario``)::

    when turtlebot within 0.8 of workbench move cylinder_red_stripes by 0.05 0.03
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path


class ScenarioError(ValueError):
    """A scenario that cannot be read or applied: the message starts with FILE:LINE:COL."""


@dataclass(frozen=True)
class Token:
    """One word of a scenario line and where it stands (1-based line and column)."""

    text: str
    line: int
    column: int


@dataclass(frozen=True)
class Condition:
    """``BODY within|beyond D of PLACE`` (``body`` set) or ``after T`` (``body`` None)."""

    body: Token | None
    relation: str  # "within", "beyond" or "after"
    value: float
    place: Token | None = None  # the body measured to; None: ``point`` or ``start``
    point: tuple[float, float] | None = None
    from_start: bool = False  # ``of start``: the measured body's position when the world was built


@dataclass(frozen=True)
class Action:
    """What an event does: ``verb`` (move-to, move-by, drop, add, remove) to ``body``."""

    verb: str
    body: Token
    numbers: tuple[float, ...] = ()
    beside: Token | None = None  # drop / add beside: the frame's body
    size: tuple[float, float, float] | None = None  # add: width, depth, height


@dataclass(frozen=True)
class Event:
    """One line of a scenario: its trigger (conditions all holding) and its action."""

    line: int
    text: str
    conditions: tuple[Condition, ...]
    action: Action


@dataclass
class Scenario:
    """A parsed scenario file: its events in file order and the boxes it adds."""

    source: str
    events: list[Event] = field(default_factory=list)

    @property
    def name(self) -> str:
        """The file's stem (``blocked-path``): how a run and its report name the scenario."""
        return Path(self.source).stem

    def where(self, token: Token) -> str:
        """``FILE:LINE:COL`` of a token."""
        return f"{self.source}:{token.line}:{token.column}"


class _Line:
    """The tokens of one line, consumed left to right; errors point at the offending token."""

    def __init__(self, source: str, number: int, text: str) -> None:
        self.source = source
        self.tokens: list[Token] = []
        column = 0
        for word in text.split():
            column = text.index(word, column)
            self.tokens.append(Token(word, number, column + 1))
            column += len(word)
        self.end = Token("", number, len(text.rstrip()) + 1)
        self.position = 0

    def error(self, token: Token, message: str) -> ScenarioError:
        return ScenarioError(f"{self.source}:{token.line}:{token.column}: {message}")

    def peek(self) -> Token | None:
        return self.tokens[self.position] if self.position < len(self.tokens) else None

    def take(self, what: str) -> Token:
        token = self.peek()
        if token is None:
            raise self.error(self.end, f"the line ends where {what} should follow")
        self.position += 1
        return token

    def word(self, *choices: str) -> Token:
        token = self.take(" or ".join(repr(c) for c in choices))
        if token.text not in choices:
            raise self.error(token, f"expected {' or '.join(repr(c) for c in choices)}, not {token.text!r}")
        return token

    def number(self, what: str, *, positive: bool = False) -> float:
        token = self.take(what)
        try:
            value = float(token.text)
        except ValueError:
            raise self.error(token, f"{what} must be a number, not {token.text!r}") from None
        if not math.isfinite(value) or (positive and value <= 0.0):
            raise self.error(token, f"{what} must be a {'positive' if positive else 'finite'} number, not {token.text}")
        return value

    def name(self, what: str) -> Token:
        token = self.take(what)
        if token.text in KEYWORDS or not token.text.replace("_", "a").replace("-", "a").isalnum():
            raise self.error(token, f"{what} must be a name, not {token.text!r}")
        return token

    def optional_number(self, what: str) -> float | None:
        token = self.peek()
        return None if token is None or token.text in KEYWORDS else self.number(what)


KEYWORDS = frozenset({"at", "when", "and", "after", "within", "beyond", "of", "point", "move", "to", "by", "drop",
                      "beside", "add", "box", "remove", "start"})  # fmt: skip


def _condition(line: _Line) -> Condition:
    token = line.peek()
    if token is not None and token.text == "after":
        line.take("after")
        return Condition(None, "after", line.number("a time (s)"))
    body = line.name("a body")
    relation = line.word("within", "beyond").text
    distance = line.number("a distance (m)")
    line.word("of")
    target = line.peek()
    if target is not None and target.text == "point":
        line.take("point")
        point = (line.number("x (m)"), line.number("y (m)"))
        return Condition(body, relation, distance, point=point)
    if target is not None and target.text == "start":
        line.take("start")
        return Condition(body, relation, distance, from_start=True)
    return Condition(body, relation, distance, place=line.name("a body, 'point X Y' or 'start'"))


def _action(line: _Line) -> Action:
    verb = line.word("move", "drop", "add", "remove")
    if verb.text == "remove":
        return Action("remove", line.name("the body to remove"))
    if verb.text == "move":
        body = line.name("the body to move")
        how = line.word("to", "by").text
        numbers = [line.number("x (m)"), line.number("y (m)")]
        z = line.optional_number("z (m)")
        return Action(f"move-{how}", body, tuple(numbers + ([] if z is None else [z])))
    if verb.text == "drop":
        body = line.name("the body to drop")
        line.word("beside")
        frame = line.name("the body it is dropped beside")
        return Action("drop", body, (line.number("dx (m)"), line.number("dy (m)")), beside=frame)
    line.word("box")
    name = line.name("the new box's name")
    size = (line.number("its width (m)", positive=True), line.number("its depth (m)", positive=True),
            line.number("its height (m)", positive=True))  # fmt: skip
    where = line.word("at", "beside")
    beside = line.name("the body it is put beside") if where.text == "beside" else None
    return Action("add", name, (line.number("x (m)"), line.number("y (m)")), beside=beside, size=size)


def parse(text: str, source: str = "<scenario>") -> Scenario:
    """The scenario of ``text`` (read from ``source``); a :class:`ScenarioError` at the first mistake."""
    scenario = Scenario(source)
    added: dict[str, Token] = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        content = raw.split("#", 1)[0]
        line = _Line(source, number, content)
        if not line.tokens:
            continue
        trigger = line.word("at", "when")
        conditions: list[Condition] = []
        if trigger.text == "at":
            conditions.append(Condition(None, "after", line.number("a time (s)")))
        else:
            conditions.append(_condition(line))
            while (after := line.peek()) is not None and after.text == "and":
                line.take("and")
                conditions.append(_condition(line))
        action = _action(line)
        extra = line.peek()
        if extra is not None:
            raise line.error(extra, f"unexpected {extra.text!r} after the action")
        if action.verb == "add":
            if action.body.text in added:
                first = added[action.body.text]
                raise line.error(action.body, f"box {action.body.text!r} is added already (line {first.line})")
            added[action.body.text] = action.body
        scenario.events.append(Event(number, content.strip(), tuple(conditions), action))
    if not scenario.events:
        raise ScenarioError(f"{source}:1:1: no event (a line 'at T ACTION' or 'when COND ACTION')")
    return scenario


def read(path: str | Path) -> Scenario:
    """Parse the scenario file ``path``; a :class:`ScenarioError` if unreadable or malformed."""
    try:
        text = Path(path).read_text()
    except (OSError, UnicodeDecodeError) as error:
        raise ScenarioError(f"{path}:1:1: cannot read the scenario: {error}") from None
    return parse(text, str(path))
