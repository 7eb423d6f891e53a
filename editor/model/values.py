"""Attribute and text values as the XSD types them: what a field accepts, why a value is refused.

The editor builds its input fields from :class:`AttributeSpec` and refuses a value the moment it
is typed. The verdict always comes from xmlschema's own simple-type decoding, so every facet of
the schema (patterns, lengths, bounds, enumerations, list items) is honoured; this module only
reads the facets to describe the field and words the refusal for people.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Literal

import xmlschema
from xmlschema.validators import (
    XsdEnumerationFacets,
    XsdLengthFacet,
    XsdMaxExclusiveFacet,
    XsdMaxInclusiveFacet,
    XsdMaxLengthFacet,
    XsdMinExclusiveFacet,
    XsdMinInclusiveFacet,
    XsdMinLengthFacet,
    XsdPatternFacets,
)
from xmlschema.validators.validation import ValidationContext

Kind = Literal["string", "int", "float", "bool", "enum", "list", "datetime"]

_XSD = "{http://www.w3.org/2001/XMLSchema}"
_SHOWN = 40  # characters of a refused value echoed back


@dataclass(frozen=True)
class AttributeSpec:
    """What one attribute (or an element's text, then named "") accepts, for forms and checks.

    ``minimum``/``maximum`` are the numeric bounds, exclusive when the matching flag is set;
    ``enumeration`` and ``item_kind`` describe list items for a ``list``.
    """

    name: str
    type_name: str
    kind: Kind
    required: bool
    default: str | None
    enumeration: tuple[str, ...]
    minimum: float | None
    maximum: float | None
    min_exclusive: bool
    max_exclusive: bool
    pattern: str | None
    documentation: str
    type_documentation: str = ""
    item_kind: Kind | None = None
    max_length: int | None = None
    fixed: str | None = None


def documentation(component: Any) -> str:
    """The xs:documentation text of a schema component, whitespace collapsed ("" when none)."""
    annotation = getattr(component, "annotation", None)
    if annotation is None:
        return ""
    texts = (" ".join("".join(doc.itertext()).split()) for doc in annotation.documentation)
    return "\n\n".join(text for text in texts if text)


def type_name(xsd_type: Any) -> str:
    """The local name of a type, or of the nearest named type it restricts."""
    while xsd_type is not None:
        if xsd_type.name:
            return str(xsd_type.local_name)
        xsd_type = getattr(xsd_type, "base_type", None)
    return ""


def kind_of(xsd_type: Any) -> Kind:
    """How an editor should present a simple type's values."""
    if xsd_type.is_list():
        return "list"
    if xsd_type.enumeration:
        return "enum"
    if xsd_type.is_union() or not xsd_type.is_atomic():
        return "string"
    if xsd_type.is_boolean():
        return "bool"
    if xsd_type.is_derived(xsd_type.maps.types[_XSD + "integer"]):
        return "int"
    if xsd_type.is_decimal() or type_name(xsd_type.primitive_type) in ("double", "float"):
        return "float"
    if xsd_type.is_datetime():
        return "datetime"
    return "string"


def value_spec(
    name: str,
    xsd_type: Any,
    *,
    required: bool,
    default: str | None = None,
    fixed: str | None = None,
    doc: str = "",
) -> AttributeSpec:
    """Describe a simple type's accepted values from its facets."""
    item = xsd_type.item_type if xsd_type.is_list() else xsd_type
    low, high = _facet(item, "minExclusive"), _facet(item, "maxExclusive")
    min_exclusive, max_exclusive = low is not None, high is not None
    low = low if low is not None else _facet(item, "minInclusive")
    high = high if high is not None else _facet(item, "maxInclusive")
    patterns = getattr(item, "patterns", None)
    longest = _facet(item, "maxLength")
    type_doc = documentation(xsd_type) if xsd_type.name else ""
    return AttributeSpec(
        name=name,
        type_name=type_name(xsd_type),
        kind=kind_of(xsd_type),
        required=required,
        default=default,
        enumeration=tuple(str(v) for v in (item.enumeration or ())),
        minimum=float(low) if low is not None else None,
        maximum=float(high) if high is not None else None,
        min_exclusive=min_exclusive,
        max_exclusive=max_exclusive,
        pattern=str(patterns.regexps[0]) if patterns is not None and patterns.regexps else None,
        documentation=doc or type_doc,
        type_documentation=type_doc,
        item_kind=kind_of(item) if item is not xsd_type else None,
        max_length=int(longest) if longest is not None else None,
        fixed=fixed,
    )


def _facet(xsd_type: Any, name: str) -> Any:
    if not hasattr(xsd_type, "get_facet"):
        return None
    return getattr(xsd_type.get_facet(_XSD + name), "value", None)


def check(spec: AttributeSpec, xsd_type: Any, text: str) -> str | None:
    """None when xmlschema accepts ``text`` for the type, else the reason, led by the field's name."""
    label = spec.name or "text"
    if spec.fixed is not None and text != spec.fixed:
        return f"{label}: must be {spec.fixed!r}"
    error = _refusal(xsd_type, text)
    if error is None:
        return None
    if not text.strip():
        return f"{label}: a value is required"
    shown = text
    if xsd_type.is_list():  # name the list item at fault, not the whole list
        for token in text.split():
            item_error = _refusal(xsd_type.item_type, token)
            if item_error is not None:
                error, shown, spec = item_error, token, _item_spec(spec, xsd_type)
                break
    return f"{label}: {_reason(error, shown, spec)}"


def _refusal(xsd_type: Any, text: str) -> xmlschema.XMLSchemaValidationError | None:
    # A context of our own: the schema's shared one is also used by the loader's validation.
    schema = xsd_type.schema
    context = ValidationContext(schema.source, namespaces=schema.namespaces)
    try:
        xsd_type.text_decode(text, "strict", context)
    except xmlschema.XMLSchemaValidationError as error:
        return error
    return None


def _item_spec(spec: AttributeSpec, xsd_type: Any) -> AttributeSpec:
    item = xsd_type.item_type
    return value_spec(spec.name, item, required=True, doc=documentation(item) if item.name else "")


def _reason(error: xmlschema.XMLSchemaValidationError, text: str, spec: AttributeSpec) -> str:
    facet, value = error.validator, _show(text)
    bound = getattr(facet, "value", None)
    if isinstance(facet, XsdMinInclusiveFacet):
        return f"{value} is below the minimum {_number(bound)}"
    if isinstance(facet, XsdMinExclusiveFacet):
        return f"{value} must be greater than {_number(bound)}"
    if isinstance(facet, XsdMaxInclusiveFacet):
        return f"{value} is above the maximum {_number(bound)}"
    if isinstance(facet, XsdMaxExclusiveFacet):
        return f"{value} must be less than {_number(bound)}"
    if isinstance(facet, XsdEnumerationFacets):
        return f"{value!r} is not one of {', '.join(str(v) for v in facet.enumeration)}"
    if isinstance(facet, XsdMaxLengthFacet):
        return f"{value!r} is longer than {bound} characters"
    if isinstance(facet, XsdMinLengthFacet):
        return "a value is required" if bound == 1 else f"{value!r} is shorter than {bound} characters"
    if isinstance(facet, XsdLengthFacet):
        return f"{value!r} must be exactly {bound} characters long"
    if spec.kind in ("int", "float") and not _is_number(text):
        return f"{value!r} is not a number"
    if spec.kind == "int" and not re.fullmatch(r"\s*[+-]?\d+\s*", text):
        return f"{value!r} is not a whole number"
    if spec.kind == "bool":
        return f"{value!r} must be true or false"
    if spec.kind == "datetime":
        return f"{value!r} is not a date and time written YYYY-MM-DDThh:mm:ss, such as 2024-05-01T12:00:00Z"
    if isinstance(facet, XsdPatternFacets):
        if spec.type_documentation:
            return f"{value!r} is not a valid {spec.type_name}: {_lower_first(spec.type_documentation)}"
        return f"{value!r} does not match the pattern {facet.regexps[0]}"
    return f"{value!r} is not accepted: {str(error.reason or error.message).rstrip('.')}"


def _is_number(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False


def _number(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def _show(text: str) -> str:
    text = text.strip()
    return text if len(text) <= _SHOWN else text[: _SHOWN - 1] + "…"


def _lower_first(text: str) -> str:
    text = text.rstrip(".")
    return text[:1].lower() + text[1:]


# ---------------------------------------------------------------- initial values

_EXAMPLE = re.compile(r"""(?:such as|written|e\.g\.)\s+(?:"([^"]+)"|([^\s,;()"]+?))[.,;)]?(?:\s|$)""")


def placeholder(spec: AttributeSpec, xsd_type: Any, owner_tag: str) -> str:
    """A value the type accepts, so a freshly added element is as valid as it can be.

    Tried in order: the default, the fixed value, the first enumerated value, a number inside
    the bounds, then names and examples drawn from the documentation ("such as tcp/…:7447").
    """
    for candidate in _candidates(spec, owner_tag):
        if _refusal(xsd_type, candidate) is None:
            return candidate
    return ""


def _candidates(spec: AttributeSpec, owner_tag: str) -> list[str]:
    found = [v for v in (spec.default, spec.fixed) if v is not None]
    found.extend(spec.enumeration[:1])
    if spec.kind in ("int", "float") or spec.item_kind in ("int", "float"):
        found.append(_inside_bounds(spec))
    if spec.kind == "bool":
        found.append("false")
    if spec.name == "name":
        found.append("new_" + re.sub(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", "_", owner_tag).lower())
    for doc in (spec.documentation, spec.type_documentation):
        found.extend(quoted or bare for quoted, bare in _EXAMPLE.findall(doc))
    found.extend(v for v in (spec.name, "1.0", "0", "a") if v)
    return found


def _inside_bounds(spec: AttributeSpec) -> str:
    low, high = spec.minimum, spec.maximum
    value = 0.0
    if low is not None and (value < low or (value == low and spec.min_exclusive)):
        value = low + 1 if spec.min_exclusive else low
    if high is not None and (value > high or (value == high and spec.max_exclusive)):
        value = (low + high) / 2 if low is not None else high - 1
    whole = spec.kind == "int" or spec.item_kind == "int"
    return str(math.ceil(value)) if whole else f"{value:g}"
