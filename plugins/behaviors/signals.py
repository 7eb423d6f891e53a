"""``behavior.wait-signal`` and ``behavior.emit-signal``: structured signals between states and agents (§5.3).

``wait-signal`` is done when its input — a topic or a plan signal (``<Input topic=…>`` or ``<Input
signal=…>``) — receives a value heard after the state was entered (D268: a value left from before,
the stale status ``wait-input`` reads, never ends it), optionally only one whose payload field
``field`` (a dotted path, ``position.frame``) equals ``equals``; the value it accepted is written on
every ``<Output>`` (a topic, or the payload of a signal this state emits) and kept as ``value``.
``emit-signal`` publishes one structured payload on every output: fields given by the Param
``fields`` (``"label: parcel; priority: 2"``) and fields taken from inputs by ``take`` (``"pose:
spotted.position"``: the ``position`` field of the ``spotted`` input's value), so a signal carries
data, as a ROS 2 message does, not only the string ``emit`` sends.

Neither uses a service of its own: eq. 5.1's performance is that of the services their
``<Uses>`` name, none for a bare wait (the mission records it as null).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model import System
from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import Behavior, BehaviorContext, BehaviorStatus
from runtime.verification.entries import Entries
from runtime.verification.interfaces import Uses
from runtime.verification.manifest import ANY, MAPPING, P, Params, Ports

_MISSING = object()


def field_of(value: Any, path: str) -> Any:
    """The field at the dotted ``path`` of ``value`` (the value itself for an empty path), or None."""
    for key in path.split(".") if path else ():
        if not isinstance(value, Mapping) or key not in value:
            return None
        value = value[key]
    return value


def matches(found: Any, wanted: str) -> bool:
    """Whether a payload field ``found`` equals the Param text ``wanted`` (as a number when both are)."""
    if isinstance(found, bool):
        return wanted.lower() == str(found).lower()
    if isinstance(found, int | float):
        try:
            return float(wanted) == float(found)
        except ValueError:
            return False
    return isinstance(found, str) and found == wanted


def typed(text: str) -> Any:
    """A Param word as a payload value: an int, a float, true/false, else the text itself."""
    if text in ("true", "false"):
        return text == "true"
    for convert in (int, float):
        try:
            return convert(text)
        except ValueError:
            continue
    return text


def _param(record: BehaviorRecord, name: str) -> Any:
    return next((p for p in record.params if p.name == name), record)


class Fresh:
    """What of one input a state has not yet looked at: values heard after it was entered (D268).

    With the host's arrival count (``BehaviorContext.heard``) a value is new when the count grew since
    it was last looked at; without one, when it differs from the value seen last (equal values
    published twice then read as one)."""

    def __init__(self, behavior: Behavior, name: str, latched: bool = False) -> None:
        self.behavior, self.name = behavior, name
        self.count = None if latched else behavior.heard(name)
        self.last: Any = _MISSING if latched else behavior.read(name)
        self.latched = latched

    def take(self) -> Any:
        """The input's value if it is new (and mark it seen), else None."""
        value = self.behavior.read(self.name)
        if value is None:
            return None
        count = self.behavior.heard(self.name)
        if self.latched and self.last is _MISSING:  # a value latched before entry counts once
            new = True
        elif count is not None and self.count is not None:
            new = count > self.count
        else:
            new = value != self.last
        self.count, self.last = count, value
        return value if new else None


class WaitSignal(Behavior):
    """``behavior.wait-signal``: done on a value heard after entry (and matching); see the module docstring."""

    USES = Uses()
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("input", "", "The <Input> waited on (default: the behavior's only input)."),
        P("field", "", "Accept only a value whose field at this dotted path (e.g. 'label', 'position.frame') "
          "matches 'equals' (empty: the whole value)."),
        P("equals", "", "The text the field (or the whole value) must equal; a number compares as a number "
                        "(empty: any value, or any value that has 'field')."),
        P("latched", False, "Also accept a value received before the state was entered (a plan signal sent "
                            "earlier in the run: each is sent once and latched, §5.3)."),
    )
    PORTS = Ports(inputs={"*": ANY}, outputs={"*": ANY})

    @classmethod
    def problems(cls, record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
        """The awaited input must be one of the behavior's inputs, named when it has several."""
        names = [p.name for p in record.inputs]
        wanted = next((p.value for p in record.params if p.name == "input"), "")
        if wanted and wanted not in names:
            return [(_param(record, "input"), f"parameter 'input' = {wanted!r} is not one of its inputs ({names})")]
        if not wanted and len(names) != 1:
            return [(record, f"it waits on one input: give it one <Input> or name one with parameter 'input' "
                             f"(inputs: {names})")]
        return []

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        problems = self.problems(record, None)
        if problems:
            raise ParamError(f"{self.owner}: {problems[0][1]}")
        self.input = self.params["input"] or record.inputs[0].name
        self.value: Any = None
        self.seen = 0

    def start(self) -> None:
        """Configure the services; from now on only new values count."""
        super().start()
        self.fresh = Fresh(self, self.input, self.params["latched"])
        self.value, self.seen = None, 0

    def _wanted(self, value: Any) -> bool:
        path, wanted = self.params["field"], self.params["equals"]
        found = field_of(value, path)
        if found is None:
            return False
        return not wanted or matches(found, wanted)

    def step(self) -> BehaviorStatus:
        """Done when a new value (matching, with ``field``/``equals``) arrived; untraceable until then."""
        value = self.fresh.take()
        if value is not None:
            self.seen += 1
            if self._wanted(value):
                self.value = value
                for port in self.record.outputs:
                    self.write(port.name, value)
                self.context.log("signal heard", input=self.input)
                return BehaviorStatus(progress=1.0, done=True, detail=f"{self.input} heard")
            self.context.log("a value that does not match ignored", input=self.input)
        what = f"{self.params['field'] or 'value'} = {self.params['equals']}" if self.params["equals"] else ""
        detail = f"waiting for a new value on {self.input}" + (f" with {what}" if what else "")
        if self.seen:
            detail += f" ({self.seen} heard, none matching)"
        return BehaviorStatus(progress=0.0, detail=detail)  # untraceable: the timeout bounds it


_FIELDS = Entries("value…", count=1, most=64, noun="a field")
_TAKE = Entries("input[.field]", count=1, noun="a field")


class EmitSignal(Behavior):
    """``behavior.emit-signal``: one structured payload on every output; see the module docstring."""

    USES = Uses()
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("fields", "", "Fields given here, 'name: value; …' (a number, true/false, or text).", entries=_FIELDS),
        P("take", "", "Fields taken from inputs, 'name: input[.field]; …' (a dotted path into its value).",
          entries=_TAKE),
        P("fresh", False, "Take only input values heard after the state was entered."),
    )
    PORTS = Ports(inputs={"*": ANY}, outputs={"*": MAPPING})

    @classmethod
    def problems(cls, record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
        """It must write somewhere, and take only from its own inputs."""
        found: list[tuple[Any, str]] = []
        if not record.outputs:
            found.append((record, "it emits on its <Output> elements, and has none"))
        names = [p.name for p in record.inputs]
        take = next((p for p in record.params if p.name == "take"), None)
        try:
            entries = _TAKE.parse(take.value, "take") if take is not None else {}
        except ParamError:
            return found  # the Param check reports the syntax
        for field, (source,) in entries.items():
            if str(source).split(".", 1)[0] not in names:
                found.append((take, f"field {field!r} takes from {str(source).split('.', 1)[0]!r}, which is not "
                                    f"one of its inputs ({names})"))
        if not entries and not next((p for p in record.params if p.name == "fields" and p.value.strip()), None):
            found.append((record, "give its payload's fields: parameter 'fields' or 'take'"))
        return found

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        problems = self.problems(record, None)
        if problems:
            raise ParamError(f"{self.owner}: {problems[0][1]}")
        self.constant = {name: typed(" ".join(str(w) for w in words)) for name, words in self.params["fields"].items()}
        self.taken = {name: str(source).partition(".") for name, (source,) in self.params["take"].items()}

    def start(self) -> None:
        """Configure the services; note what each taken input holds as the state is entered."""
        super().start()
        sources = {source for source, _, _ in self.taken.values()}
        self.fresh = {s: Fresh(self, s) for s in sources} if self.params["fresh"] else {}
        self.values: dict[str, Any] = {}
        self.payload: dict[str, Any] | None = None

    def step(self) -> BehaviorStatus:
        """Done once every taken input has a value (with ``fresh``: a new one); the payload is then written."""
        if self.payload is not None:
            return BehaviorStatus(progress=1.0, done=True)
        for source, fresh in self.fresh.items():
            if source not in self.values and (value := fresh.take()) is not None:
                self.values[source] = value
        payload = dict(self.constant)
        for name, (source, _, path) in self.taken.items():
            value = self.values.get(source) if self.fresh else self.read(source)
            found = field_of(value, path)
            if found is None:
                return BehaviorStatus(progress=0.0, detail=f"waiting for {source}" + (f".{path}" if path else ""))
            payload[name] = found
        self.payload = payload
        for port in self.record.outputs:
            self.write(port.name, payload)
        self.context.log("signal payload written", fields=sorted(payload))
        return BehaviorStatus(progress=1.0, done=True)
