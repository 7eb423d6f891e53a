"""Generic mapping between XML elements and frozen record dataclasses (the XSD model of §3.1.5.1).

Each record class declares its fields with ``attr()``, ``child()``, ``children()`` or
``text()``; the type hints say how values convert. One reader and one writer then serve
every element kind, so adding an element to the XSD means adding one small dataclass.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Callable
from dataclasses import MISSING, dataclass, field
from typing import Any, ClassVar, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

from lxml import etree

from .errors import Loc
from .source import NAMESPACE, SourceFile

NS = "{" + NAMESPACE + "}"

_KEY = "ckm"


def attr(*, xml: str | None = None, default: Any = MISSING) -> Any:
    """An XML attribute; the XML name is the field name in camelCase unless given."""
    return field(default=default, metadata={_KEY: ("attr", xml)})


def child(*, default: Any = MISSING) -> Any:
    """A single child element (its tag is the record class's TAG)."""
    return field(default=default, metadata={_KEY: ("child", None)})


def children() -> Any:
    """A sequence of child elements of one or several record kinds, in document order."""
    return field(default=(), metadata={_KEY: ("children", None)})


def text() -> Any:
    """The element's own text content (a simple-content element such as a matrix Row)."""
    return field(metadata={_KEY: ("text", None)})


@dataclass(frozen=True, kw_only=True)
class Record:
    """Base of every configuration record (one XSD element, §3.1.5.1); ``loc`` says where it was read (not compared)."""

    TAG: ClassVar[str] = ""
    loc: Loc | None = field(default=None, compare=False, repr=False)


R = TypeVar("R", bound=Record)


def camel(name: str) -> str:
    """XML attribute name of a Python field: ``max_frame`` → ``maxFrame`` (a trailing ``_`` dropped: ``type_``)."""
    head, *rest = name.rstrip("_").split("_")
    return head + "".join(part[:1].upper() + part[1:] for part in rest)


@dataclass(frozen=True)
class FieldPlan:
    """How one record field maps to XML: ``kind`` (attr/child/children/text), XML name, converters, default."""

    name: str
    kind: str
    xml: str
    parse: Callable[[str], Any] | None
    write: Callable[[Any], str] | None
    classes: dict[str, type[Record]]
    default: Any


def format_float(value: float) -> str:
    """Shortest text that reads back to ``value``, without a trailing ``.0`` (``2.0`` → ``2``)."""
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def _scalar(kind: Any) -> tuple[Callable[[str], Any], Callable[[Any], str]]:
    if kind is bool:
        return (lambda s: s.strip() in ("true", "1")), (lambda v: "true" if v else "false")
    if kind is int:
        return (lambda s: int(s.strip())), str
    if kind is float:
        return (lambda s: float(s.strip())), format_float
    if kind is str or get_origin(kind) is Literal:
        return (lambda s: s.strip()) if kind is not str else (lambda s: s), str
    raise TypeError(f"unsupported attribute type {kind!r}")


def _converters(kind: Any) -> tuple[Callable[[str], Any], Callable[[Any], str]]:
    if get_origin(kind) is tuple:
        item_parse, item_write = _scalar(get_args(kind)[0])
        return (lambda s: tuple(item_parse(x) for x in s.split())), (lambda v: " ".join(item_write(x) for x in v))
    return _scalar(kind)


def _strip_optional(kind: Any) -> Any:
    if get_origin(kind) in (Union, types.UnionType):
        args = [a for a in get_args(kind) if a is not type(None)]
        return args[0] if len(args) == 1 else Union[tuple(args)]  # noqa: UP007 - rebuilt at run time
    return kind


def _record_classes(kind: Any) -> dict[str, type[Record]]:
    options = get_args(kind) if get_origin(kind) in (Union, types.UnionType) else (kind,)
    found: dict[str, type[Record]] = {}
    for option in options:
        if isinstance(option, type) and issubclass(option, Record):
            found[option.TAG] = option
    return found


_PLANS: dict[type[Record], tuple[FieldPlan, ...]] = {}


def plan(cls: type[Record]) -> tuple[FieldPlan, ...]:
    """How each field of a record class maps to XML (computed once per class)."""
    found = _PLANS.get(cls)
    if found is None:
        found = _PLANS[cls] = _make_plan(cls)
    return found


def _make_plan(cls: type[Record]) -> tuple[FieldPlan, ...]:
    hints = get_type_hints(cls)
    plans: list[FieldPlan] = []
    for f in dataclasses.fields(cls):
        meta = f.metadata.get(_KEY)
        if meta is None:
            continue
        kind, xml = meta
        hint = _strip_optional(hints[f.name])
        default = f.default if f.default is not MISSING else MISSING
        if kind == "attr":
            parse, write = _converters(hint)
            plans.append(FieldPlan(f.name, kind, xml or camel(f.name), parse, write, {}, default))
        elif kind == "child":
            plans.append(FieldPlan(f.name, kind, "", None, None, _record_classes(hint), default))
        elif kind == "children":
            plans.append(FieldPlan(f.name, kind, "", None, None, _record_classes(get_args(hint)[0]), default))
        else:
            parse, write = _converters(hint)
            plans.append(FieldPlan(f.name, kind, "", parse, write, {}, default))
    return tuple(plans)


def bind(cls: type[R], element: etree._Element, source: SourceFile) -> R:
    """Build a record from a schema-valid element."""
    values: dict[str, Any] = {"loc": source.loc(element)}
    kids = [(k.tag[len(NS) :], k) for k in element if isinstance(k.tag, str) and k.tag.startswith(NS)]
    for p in plan(cls):
        if p.kind == "attr":
            raw = element.get(p.xml)
            if raw is not None and p.parse is not None:
                values[p.name] = p.parse(raw)
        elif p.kind == "child":
            for tag, kid in kids:
                if tag in p.classes:
                    values[p.name] = bind(p.classes[tag], kid, source)
                    break
        elif p.kind == "children":
            values[p.name] = tuple(bind(p.classes[tag], kid, source) for tag, kid in kids if tag in p.classes)
        elif p.parse is not None:
            values[p.name] = p.parse(element.text or "")
    return cls(**values)


def unbind(record: Record, parent: etree._Element | None = None) -> etree._Element:
    """Write a record as an element (defaults and absent values are left out)."""
    tag = NS + record.TAG
    nsmap: dict[Any, str] = {None: NAMESPACE}
    element = etree.Element(tag, nsmap=nsmap) if parent is None else etree.SubElement(parent, tag)
    for p in plan(type(record)):
        value = getattr(record, p.name)
        if p.kind == "attr":
            if value is None or (p.default is not MISSING and value == p.default):
                continue
            assert p.write is not None
            element.set(p.xml, p.write(value))
        elif p.kind == "child":
            if value is not None:
                unbind(value, element)
        elif p.kind == "children":
            for item in value:
                unbind(item, element)
        elif p.write is not None:
            element.text = p.write(value)
    return element


def walk(record: Record) -> typing.Iterator[Record]:
    """Every record in a tree, parents before children, in document order."""
    yield record
    for p in plan(type(record)):
        if p.kind == "child":
            value = getattr(record, p.name)
            if value is not None:
                yield from walk(value)
        elif p.kind == "children":
            for item in getattr(record, p.name):
                yield from walk(item)
