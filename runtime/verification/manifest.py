"""The manifest of a kind: its parameters and the values it exchanges (BehaviorTree.CPP's manifests).

Every registered class declares, once, at the class:

- ``PARAMS``: a :class:`Params` of :class:`P` entries — name, type, default (or required), unit,
  range, accepted values and a one-line doc. The same object converts the ``<Param>`` elements
  when the kind is built (:func:`read_params`) and is what ``verify`` checks a configuration
  against before anything is built, so the two can never disagree.
- ``PORTS`` (optional): a :class:`Ports` naming the value types of its inputs and outputs
  (controllers by role, behaviors by port name, ``"*"`` for any) and, for hardware backends, the
  channel sizes it serves. A backend whose reads depend on its Params (a simulated camera reads
  images, a simulated joint numbers) may instead define a classmethod ``value_type(channel) ->
  str`` (static: no I/O, no instance). Value types are the names of ``schemas/kernel.xsd`` (built-in types
  such as ``float64`` or ``string``, or a ``MessageType``) or the shapes :data:`NUMBER`,
  :data:`NUMBERS` (a vector of numbers, one per channel element), :data:`MAPPING` (a dict of
  fields), :data:`ARRAY` (an n-dimensional numeric array: an image, a depth frame) and :data:`ANY`.
  Processing plugins declare what their ``process`` accepts (``inputs["*"]``; with several service
  Inputs the value is a dict and each Input is checked against the entry of its name) and returns
  (``outputs["*"]``; with several service Outputs, the entry of each Output's name is its field).

A plain ``{name: default}`` mapping is still accepted as ``PARAMS`` (third-party plugins written
before manifests): each entry then reads as an undocumented optional parameter of its default's type.
"""

from __future__ import annotations

import math
import os
import pathlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from ckmconf import ConfigError, ConfigErrors, read_document
from ckmconf.errors import MEMORY_FILE
from ckmconf.model import Param, params_dict

from .entries import Entries, ParamError, Parsed

NUMBER = "number"
"""One number (a float): what sensors of size-1 channels and controllers write, actuators take."""
NUMBERS = "numbers"
"""A tuple of numbers: what a sensor of a channel of size > 1 writes."""
MAPPING = "mapping"
"""A dict of fields: fits a topic of any MessageType, no built-in type; a service Output's type must
hold the fields its kind writes (``WRITES``, or its interface port's: verification.message_checks)."""
ARRAY = "array"
"""An n-dimensional numeric array (an image, a depth frame): travels only as ``bytes`` (the codec's encoding)."""
ANY = "any"
"""Not declared: any value (nothing to check)."""

FILE = "file"
"""``P(file=FILE)``: the value names a file, relative to the configuration file, that must exist."""
ENVIRONMENT_FILE = "environment"
"""``P(file=ENVIRONMENT_FILE)``: the value names a configuration file holding an ``<Environment>``."""

ParamType = type[bool] | type[int] | type[float] | type[str]
_TYPE_NAMES: dict[type, str] = {bool: "bool", int: "int", float: "float", str: "string"}


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED: Any = _Required()
"""The default of a parameter that must be given."""


def _number(value: float) -> str:
    return f"{value:g}" if math.isfinite(value) else ("inf" if value > 0 else "-inf")


@dataclass(frozen=True)
class P:
    """One declared parameter, read from a ``<Param name value>`` element.

    ``default`` is :data:`REQUIRED` for a parameter that must be given, or None for one whose default
    the kind computes from its element (say so in ``doc``).

    ``min``/``max`` bound the value inclusively, ``above``/``below`` strictly; ``choices`` lists
    the accepted values. The type is the default's unless ``type`` is given. ``entries`` declares a
    per-name string value (``"name: v1 v2; …"``, :class:`~runtime.verification.entries.Entries`):
    the kind then receives it parsed, ``{name: (values…)}``. ``file`` marks a path relative to the
    configuration file the ``<Param>`` is in, which must exist: :data:`FILE` any file,
    :data:`ENVIRONMENT_FILE` one that holds an ``<Environment>`` (an empty value: none given).
    ``place`` marks a place on the map: a pose ``"x y yaw"`` or the name of an Area or Object of the
    system's ``<Environment>`` (checked when the system has one; an empty value: none given).
    ``numbers`` gives the counts of whitespace-separated finite numbers a string value may hold
    (``(3,)`` for ``"x y yaw"``), ``form`` how messages show them (``"'x y yaw'"``); an empty value
    of a parameter that is not required passes.
    """

    name: str
    default: Any
    doc: str = ""
    type: ParamType | None = None
    unit: str = ""
    min: float | None = None
    max: float | None = None
    above: float | None = None
    below: float | None = None
    choices: tuple[Any, ...] = ()
    entries: Entries | None = None
    file: str = ""
    place: bool = False
    numbers: tuple[int, ...] = ()
    form: str = ""

    def __post_init__(self) -> None:
        if self.type is None:
            if self.default is REQUIRED or self.default is None:
                raise TypeError(f"parameter {self.name!r}: give its type when it has no default")
            object.__setattr__(self, "type", type(self.default) if type(self.default) in _TYPE_NAMES else str)

    @property
    def required(self) -> bool:
        """True if the ``<Param>`` must be given (no default)."""
        return self.default is REQUIRED

    @property
    def type_name(self) -> str:
        """The parameter's type as the manifest reference shows it (``float``, ``int``, ``bool``, ``string``)."""
        assert self.type is not None
        return _TYPE_NAMES[self.type]

    def range_text(self) -> str:
        """The accepted values in words ("" when any value of the type is)."""
        if self.choices:
            return "one of " + ", ".join(str(c) for c in self.choices)
        if self.entries is not None:
            return self.entries.syntax()
        if self.numbers:
            return " or ".join(str(n) for n in self.numbers) + " numbers"
        low = high = ""
        if self.min is not None or self.above is not None:
            low = f"[{_number(self.min)}" if self.min is not None else f"({_number(self.above or 0.0)}"
        if self.max is not None or self.below is not None:
            high = f"{_number(self.max)}]" if self.max is not None else f"{_number(self.below or 0.0)})"
        if not low and not high:
            return ""
        return f"{low or '(-inf'}, {high or 'inf)'}"

    def default_text(self) -> str:
        """The default as documentation shows it: ``required``, ``computed`` or the value."""
        if self.required:
            return "required"
        if self.default is None:
            return "computed"
        if isinstance(self.default, bool):
            return "true" if self.default else "false"
        if isinstance(self.default, float):
            return _number(self.default)
        return repr(self.default) if isinstance(self.default, str) else str(self.default)

    def convert(self, text: str) -> Any:
        """The typed value of ``text`` (a per-name value parsed); ParamError saying why it is not acceptable."""
        if self.entries is not None:
            return self.entries.parse(text, self.name)
        try:
            if self.type is bool:
                if text not in ("true", "false", "1", "0"):
                    raise ValueError(text)
                value: Any = text in ("true", "1")
            elif self.type is int:
                value = int(text)
            elif self.type is float:
                value = float(text)
            else:
                value = text
        except ValueError:
            assert self.type is not None
            raise ParamError(f"parameter {self.name!r} = {text!r} is not a {self.type.__name__}") from None
        problem = self.out_of_range(value)
        if problem:
            shown = repr(value) if isinstance(value, str) else str(value)
            raise ParamError(f"parameter {self.name!r} = {shown} {problem}")
        if self.numbers and isinstance(value, str) and (value.strip() or self.required):
            self._check_numbers(value)
        return value

    def _check_numbers(self, text: str) -> None:
        counts = " or ".join(str(n) for n in self.numbers)
        try:
            values = [float(v) for v in text.split()]
        except ValueError:
            values = []
        if len(values) not in self.numbers or not all(math.isfinite(v) for v in values):
            shape = f"{self.form} ({counts} finite numbers)" if self.form else f"{counts} finite numbers"
            raise ParamError(f"parameter {self.name!r} = {text!r} is not {shape}")

    def out_of_range(self, value: Any) -> str:
        """Why ``value`` is outside the declared range, as the end of a sentence ("" when inside)."""
        if self.choices and value not in self.choices:
            return "must be one of " + ", ".join(str(c) for c in self.choices)
        if isinstance(value, bool) or not isinstance(value, int | float):
            return ""
        if self.min is not None and value < self.min:
            return "must not be negative" if self.min == 0 else f"must be at least {_number(self.min)}"
        if self.above is not None and not value > self.above:
            return f"must be greater than {_number(self.above)}"
        if self.max is not None and value > self.max:
            return f"must be at most {_number(self.max)}"
        if self.below is not None and not value < self.below:
            return f"must be less than {_number(self.below)}"
        return ""


class Params(Mapping[str, Any]):
    """The parameters (``<Param>``) of a kind, in declaration order; as a mapping, name → default."""

    def __init__(self, *specs: P) -> None:
        self.specs: dict[str, P] = {}
        for spec in specs:
            if spec.name in self.specs:
                raise TypeError(f"parameter {spec.name!r} is declared twice")
            self.specs[spec.name] = spec

    def __getitem__(self, name: str) -> Any:
        return self.specs[name].default

    def __iter__(self) -> Iterator[str]:
        return iter(self.specs)

    def __len__(self) -> int:
        return len(self.specs)

    def __or__(self, other: Mapping[str, Any]) -> Params:
        """Both sets of parameters (``other`` wins on a name both declare)."""
        merged = dict(self.specs)
        merged.update(as_params(other).specs)
        return Params(*merged.values())

    def __repr__(self) -> str:
        return f"Params({', '.join(self.specs)})"


def as_params(declared: Mapping[str, Any]) -> Params:
    """``declared`` as a Params (a plain mapping reads as undocumented optional parameters)."""
    if isinstance(declared, Params):
        return declared
    return Params(*(P(name, default) for name, default in declared.items()))


@dataclass(frozen=True)
class Ports:
    """The value types a kind reads and writes, and the channel sizes a backend serves.

    ``inputs``/``outputs`` map a role (controllers) or port name (behaviors) to a value type;
    the key ``"*"`` covers every other one. ``sizes``: the channel sizes a hardware backend
    accepts (empty: any).
    """

    inputs: Mapping[str, str] = field(default_factory=lambda: {"*": ANY})
    outputs: Mapping[str, str] = field(default_factory=lambda: {"*": ANY})
    sizes: tuple[int, ...] = ()

    def input(self, name: str) -> str:
        """Value type read on input ``name`` (or role), falling back to ``"*"``, then :data:`ANY`."""
        return self.inputs.get(name, self.inputs.get("*", ANY))

    def output(self, name: str) -> str:
        """Value type written on output ``name`` (or role), falling back to ``"*"``, then :data:`ANY`."""
        return self.outputs.get(name, self.outputs.get("*", ANY))


def params_of(cls: type) -> Params:
    """The declared parameters of a registered class (none declared: none accepted)."""
    return as_params(getattr(cls, "PARAMS", Params()))


def ports_of(cls: type) -> Ports:
    """The declared ports of a registered class (none declared: anything goes)."""
    ports = getattr(cls, "PORTS", None)
    return ports if isinstance(ports, Ports) else Ports()


def read_params(
    params: Sequence[Param],
    spec: Mapping[str, Any],
    *,
    owner: str,
    defaults: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Typed parameter values from the ``<Param>`` elements, checked against the declaration.

    Args:
        params: the element's Params.
        spec: the kind's ``PARAMS`` (a :class:`Params`, or a plain name → default mapping).
        owner: how messages name the element ("controller 'left_pid' (pid)").
        defaults: values for parameters whose default the kind computes (declared default None).

    Returns:
        Every declared parameter by name, given or defaulted.

    Raises:
        ParamError: an unknown or missing parameter, or a value of the wrong type or out of range.
    """
    declared = as_params(spec)
    given = params_dict(tuple(params))
    unknown = sorted(set(given) - set(declared))
    if unknown:
        accepted = ", ".join(sorted(declared)) or "none"
        raise ParamError(f"{owner} takes no parameter {unknown[0]!r} (accepted: {accepted})")
    values: dict[str, Any] = {}
    for name, entry in declared.specs.items():
        if name in given:
            try:
                values[name] = entry.convert(given[name])
            except ParamError as exc:
                raise ParamError(f"{owner}: {exc}", exc.offset) from None
        elif entry.required:
            raise ParamError(f"{owner} needs parameter {name!r} ({entry.doc or entry.type_name})")
        else:
            values[name] = defaulted(entry, (defaults or {}).get(name, entry.default))
    for _, problem in strays(declared, values, given):
        raise ParamError(f"{owner}: {problem}", problem.offset)
    return values


def defaulted(entry: P, value: Any) -> Any:
    """A parameter's default as the kind receives it (a per-name default parsed like a given value)."""
    return entry.entries.parse(value, entry.name) if entry.entries is not None and isinstance(value, str) else value


def strays(declared: Params, values: Mapping[str, Any], given: Mapping[str, str]) -> Iterator[tuple[str, ParamError]]:
    """(Param name, problem) for each per-name entry naming what its ``of`` Param does not hold.

    Args:
        declared: the kind's parameters.
        values: every parameter's value, parsed (given or defaulted).
        given: the text of the given ones, to place each problem at its entry.
    """
    for name, entry in declared.specs.items():
        value = values.get(name)
        if entry.entries is not None and isinstance(value, dict):
            for problem in entry.entries.strays(name, value, given.get(name), values):
                yield name, problem


@dataclass(frozen=True)
class ParamProblem:
    """One Param that does not fit its kind's declaration, where ``verify`` places it.

    ``param`` is None for a required Param not given (placed at the owning element); ``attr`` and
    ``offset`` name the attribute and the character of its value (a per-name entry).
    """

    param: Param | None
    message: str
    attr: str | None = None
    offset: int | None = None


def param_problems(cls: type, params: Sequence[Param], owner: str) -> list[ParamProblem]:
    """Every ``<Param>`` of ``params`` against the declaration of kind ``cls``, with the conversions
    ``read_params`` makes to build it: one check for ``verify`` and for a delegated plugin's description.

    Args:
        cls: the registered class.
        params: the element's Params.
        owner: how messages name the element ("plugin kind 'resize'").
    """
    declared = params_of(cls)
    problems: list[ParamProblem] = []
    given: dict[str, Param] = {}
    values: dict[str, Any] = {}
    for param in params:
        given[param.name] = param
        entry = declared.specs.get(param.name)
        if entry is None:
            accepted = ", ".join(sorted(declared)) or "none"
            problems.append(ParamProblem(param, f"{owner} takes no parameter {param.name!r} (accepted: {accepted})",
                                         "name"))
            continue
        try:
            values[param.name] = entry.convert(param.value)
        except ParamError as exc:
            problems.append(ParamProblem(param, f"{owner}: {exc}", "value", exc.offset))
            continue
        missing = file_problem(entry, param)
        if missing:
            problems.append(ParamProblem(param, f"{owner}: parameter {param.name!r} = {param.value!r}: {missing}",
                                         "value"))
    for name, entry in declared.specs.items():
        if entry.required and name not in given:
            problems.append(ParamProblem(None, f"{owner} needs parameter {name!r} ({entry.doc or entry.type_name})"))
        elif name not in given and not entry.required:
            try:
                values[name] = defaulted(entry, entry.default)
            except ParamError:
                continue  # the kind's own default: not the configuration's problem
    for name, problem in strays(declared, values, {n: p.value for n, p in given.items()}):
        at = given.get(name)
        if at is None:
            problems.append(ParamProblem(None, f"{owner}: {problem}"))
        else:
            problems.append(ParamProblem(at, f"{owner}: {problem}", "value", problem.offset))
    return problems


def file_problem(entry: P, param: Param) -> str:
    """Why the file ``param`` names cannot serve ``entry`` ("" when it can, or names none, or the Param
    was built in code): it is resolved as the kinds resolve it, next to the Param's own file."""
    if not entry.file or not param.value or param.loc is None or param.loc.file == MEMORY_FILE:
        return ""
    path = pathlib.Path(os.path.abspath(param.loc.file)).parent / param.value
    if not path.is_file():
        shown = os.path.relpath(path)
        return f"no such file {path if shown.startswith('..') else shown}"
    if entry.file != ENVIRONMENT_FILE:
        return ""
    try:
        document = read_document(path)
    except ConfigError as exc:
        return f"cannot read it: {exc}"
    except ConfigErrors as exc:
        return f"cannot read it: {exc.errors[0]}"
    return "" if document.environment is not None else f"{param.value} holds no <Environment>"


__all__ = [
    "ANY",
    "ARRAY",
    "ENVIRONMENT_FILE",
    "FILE",
    "MAPPING",
    "NUMBER",
    "NUMBERS",
    "REQUIRED",
    "Entries",
    "P",
    "ParamError",
    "ParamProblem",
    "Params",
    "Parsed",
    "Ports",
    "as_params",
    "defaulted",
    "file_problem",
    "param_problems",
    "params_of",
    "ports_of",
    "read_params",
    "strays",
]


def fixed_numbers(text: str, count: int, name: str, owner: str) -> list[float]:
    """Exactly ``count`` finite numbers from a string Param such as a pose ``"x y yaw"``, else ParamError."""
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise ParamError(f"{owner}: parameter {name!r} = {text!r} is not {count} numbers")
    return values
