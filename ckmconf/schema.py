"""XSD validation (schemas/ckm.xsd, §3.1.5.2) with xmlschema, and the translation of its findings into plain messages.

The schema files in ``schemas/`` are the single source of truth; this module only loads
them (sandboxed: no network, no file outside the schema folder) and words the errors the
same way every time, naming the attribute or child element at fault.
"""

from __future__ import annotations

import os
import re
from functools import lru_cache
from pathlib import Path
from typing import Any

import xmlschema
from lxml import etree

from .errors import ConfigError
from .source import NAMESPACE, SourceFile, in_namespace, local_name

SUPPORTED_MAJOR = 1
MAX_PROBLEMS = 100  # per file: a hostile file must not produce unbounded output
# xmlschema needs ~30 µs per element, and time quadratic in the unknown children of one parent;
# past these bounds libxml2's findings (one per content model, in C) are reported instead.
XMLSCHEMA_MAX_ELEMENTS = 100_000
XMLSCHEMA_MAX_FANOUT_COST = 1_000_000
ROOTS = ("System", "Part")


def schema_dir() -> Path:
    """The folder holding ckm.xsd (``CKM_SCHEMA_DIR`` overrides the repository's ``schemas/``)."""
    override = os.environ.get("CKM_SCHEMA_DIR")
    return Path(override) if override else Path(__file__).resolve().parent.parent / "schemas"


@lru_cache(maxsize=1)
def schema() -> xmlschema.XMLSchema10:
    """The CKM schema, loaded once per process."""
    return xmlschema.XMLSchema10(str(schema_dir() / "ckm.xsd"), allow="sandbox", defuse="always")


@lru_cache(maxsize=1)
def fast_schema() -> etree.XMLSchema:
    """The same schema compiled by libxml2: the fast first pass for files that are valid."""
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)
    return etree.XMLSchema(etree.parse(str(schema_dir() / "ckm.xsd"), parser))


def validate(source: SourceFile) -> list[ConfigError]:
    """Every schema violation of one parsed file, located and worded plainly."""
    root = source.root
    tag = root.tag if isinstance(root.tag, str) else ""
    name = local_name(tag)
    if not tag.startswith("{" + NAMESPACE + "}"):
        if name in ROOTS:
            message = f'root element {name!r} must be in the namespace {NAMESPACE} (add xmlns="{NAMESPACE}")'
        else:
            message = f"root element must be System or Part in the namespace {NAMESPACE}, not {name!r}"
        return [ConfigError.at(source.loc(root), message)]
    if name not in ROOTS:
        return [ConfigError.at(source.loc(root), f"root element must be System or Part, not {name!r}")]
    version_error = _check_version(source)
    if version_error is not None:
        return [version_error]
    # libxml2 answers "valid" in milliseconds; only a file it rejects pays for xmlschema, whose
    # findings carry what is needed to word and locate each problem.
    checker = fast_schema()
    if checker.validate(root.getroottree()):
        return []
    if source.elements > XMLSCHEMA_MAX_ELEMENTS:
        return _libxml2_errors(source, checker)
    flood = _unknown_children_flood(source)
    if flood:
        return flood
    resource = xmlschema.XMLResource(root.getroottree(), allow="none", defuse="always")
    errors: list[ConfigError] = []
    for error in schema().iter_errors(resource):
        if len(errors) == MAX_PROBLEMS:
            errors.append(
                ConfigError(source.path, 1, 1, "/", f"more problems follow; the first {MAX_PROBLEMS} are shown")
            )
            break
        translated = _translate(source, error)
        if str(translated) not in {str(e) for e in errors}:  # a word for a number fails each facet: one line
            errors.append(translated)
    return errors or _libxml2_errors(source, checker)  # never pass a file libxml2 refused


def _libxml2_errors(source: SourceFile, checker: etree.XMLSchema) -> list[ConfigError]:
    entries = list(checker.error_log)[:MAX_PROBLEMS]  # type: ignore[call-overload]
    return [_libxml2_error(source, entry) for entry in entries]


_NOT_EXPECTED = re.compile(r"Element '([^']+)': This element is not expected\.(?: Expected is one of \( (.*) \))?")


def _libxml2_error(source: SourceFile, entry: Any) -> ConfigError:
    found: Any = source.root.getroottree().xpath(str(entry.path)) if entry.path else []
    element = found[0] if isinstance(found, list) and found and isinstance(found[0], etree._Element) else source.root
    message = re.sub(r"\{[^}]*\}", "", str(entry.message)).strip().rstrip(".")
    if match := _NOT_EXPECTED.match(message):
        parent = element.getparent()
        owner = local_name(parent.tag) if parent is not None else "the document"
        allowed = ", ".join(local_name(t) for t in _allowed_children(parent)) if parent is not None else ""
        message = f"unexpected element {match.group(1)!r} in {owner}" + (f" (allowed: {allowed})" if allowed else "")
    return ConfigError.at(source.loc(element), shorten(message, 300))


def _unknown_children_flood(source: SourceFile) -> list[ConfigError]:
    """Unknown child elements by the thousand: report the first ones without xmlschema's quadratic pass."""
    allowed_by_decl: dict[int, set[str]] = {}
    flooded = False
    unknown: list[etree._Element] = []
    for parent in source.root.iter():
        if not isinstance(parent.tag, str) or len(parent) < 100:
            continue
        decl = element_declaration(parent)
        if decl is None:
            continue
        allowed = allowed_by_decl.setdefault(id(decl), set(child_declarations(decl)))
        strays = [
            c
            for c in parent
            if isinstance(c.tag, str) and (not in_namespace(c.tag) or local_name(c.tag) not in allowed)
        ]
        flooded = flooded or len(strays) * len(parent) > XMLSCHEMA_MAX_FANOUT_COST
        unknown.extend(strays[: MAX_PROBLEMS + 1])
    if not flooded:
        return []
    errors = [ConfigError.at(source.loc(child), _stray_message(child)) for child in unknown[: MAX_PROBLEMS + 1]]
    if len(errors) > MAX_PROBLEMS:
        errors[-1] = _more(errors[-1])
    return errors


def _more(next_problem: ConfigError) -> ConfigError:
    """Where the first problem past the limit is, and that no more are listed."""
    message = f"more problems from here on; only the first {MAX_PROBLEMS} are listed"
    return ConfigError(next_problem.file, next_problem.line, next_problem.column, next_problem.xpath, message)


def _stray_message(child: etree._Element) -> str:
    parent = child.getparent()
    owner = local_name(parent.tag) if parent is not None else "the document"
    if not in_namespace(child.tag):
        return f"element {local_name(child.tag)!r} is not in the CKM namespace {NAMESPACE}"
    allowed = ", ".join(_allowed_children(parent)) if parent is not None else ""
    return f"unexpected element {local_name(child.tag)!r} in {owner} (allowed: {allowed})"


def _check_version(source: SourceFile) -> ConfigError | None:
    version = source.root.get("version")
    if version is None:
        return None  # the schema reports the missing attribute
    match = re.fullmatch(r"(\d+)\.(\d+)", version.strip())
    if match and int(match.group(1)) != SUPPORTED_MAJOR:
        return ConfigError.at(
            source.attr_loc(source.root, "version"),
            f"unsupported model version {version!r}: this release reads {SUPPORTED_MAJOR}.x",
        )
    return None


_ATTRIBUTE_VALUE = re.compile(r"^attribute (?P<name>[^=\s]+)=")
_UNKNOWN_ATTRIBUTE = re.compile(r"^'(?P<name>[^']+)' attribute not allowed")
_MISSING_ATTRIBUTE = re.compile(r"^missing required attribute '(?P<name>[^']+)'")
_UNEXPECTED_CHILD = re.compile(r"^Unexpected child with tag '(?P<tag>[^']+)' at position (?P<pos>\d+)")
_INCOMPLETE = re.compile(r"^The content of element '[^']+' is not complete")


def _translate(source: SourceFile, error: Any) -> ConfigError:
    element = error.elem if isinstance(error.elem, etree._Element) else source.root
    reason = str(error.reason or error.message)
    owner = local_name(element.tag)
    if match := _ATTRIBUTE_VALUE.match(reason):
        attr = match.group("name")
        decl = _attribute_decl(error, attr)
        raw = shorten(element.get(attr, ""))
        return ConfigError.at(source.attr_loc(element, attr), f"invalid {attr} {raw!r}: {_expectation(decl, reason)}")
    if match := _UNKNOWN_ATTRIBUTE.match(reason):
        attr = match.group("name")
        allowed = ", ".join(_allowed_attributes(error))
        return ConfigError.at(
            source.attr_loc(element, attr), f"unknown attribute {attr!r} on {owner} (allowed: {allowed})"
        )
    if match := _MISSING_ATTRIBUTE.match(reason):
        return ConfigError.at(source.loc(element), f"{owner} is missing the required attribute {match.group('name')!r}")
    if match := _UNEXPECTED_CHILD.match(reason):
        return _unexpected_child(source, element, error, int(match.group("pos")))
    if _INCOMPLETE.match(reason):
        expected = [local_name(t) for t in (getattr(error, "expected_tags", None) or [])]
        if not expected:
            expected = re.findall(r"Tag '\{[^}]*\}([^']+)'", reason) or re.findall(r"Tag '([^']+)'", reason)
        wanted = " or ".join(expected) if expected else "more elements"
        return ConfigError.at(source.loc(element), f"{owner} is incomplete: missing {wanted}")
    if "character data" in reason or "has no mixed content" in reason:
        return ConfigError.at(source.text_loc(element), f"text is not allowed inside {owner}")
    if error.elem is not None and len(element) == 0 and element.text is not None:
        decl = getattr(_xsd_element(error), "type", None)
        text = shorten(element.text.strip())
        return ConfigError.at(
            source.text_loc(element), f"invalid {owner} content {text!r}: {_expectation(decl, reason)}"
        )
    return ConfigError.at(source.loc(element), shorten(reason.rstrip("."), 300))


def shorten(text: str, limit: int = 60) -> str:
    """Values echoed in messages are cut, so a hostile 5 MB value makes a short line."""
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _unexpected_child(source: SourceFile, element: etree._Element, error: Any, position: int) -> ConfigError:
    # xmlschema counts comments and processing instructions too; prefer the element it names.
    named = getattr(error, "invalid_child", None)
    if isinstance(named, etree._Element) and named.getparent() is element:
        child = named
    else:
        child = element[position - 1] if 0 < position <= len(element) else element
    if not isinstance(child.tag, str):
        child = element
    tag = child.tag if isinstance(child.tag, str) else ""
    name = local_name(tag)
    owner = local_name(element.tag)
    allowed = _allowed_children(element)
    if not tag.startswith("{" + NAMESPACE + "}"):
        message = f"element {name!r} is not in the CKM namespace {NAMESPACE}"
    elif name in allowed:
        before = next(child.itersiblings(child.tag, preceding=True), None)
        if before is not None and _max_occurs(element, name) == 1:
            message = f"{owner} may hold only one {name}"
        else:
            message = f"{name} is out of place: {owner} holds its children in this order: {', '.join(allowed)}"
    elif allowed:
        message = f"unexpected element {name!r} in {owner} (allowed: {', '.join(allowed)})"
    else:
        message = f"{owner} takes no child elements, found {name!r}"
    return ConfigError.at(source.loc(child), message)


# ---------------------------------------------------------------- schema introspection


def element_declaration(element: etree._Element) -> Any:
    """The xmlschema declaration of a CKM element, found by walking down from the root."""
    chain: list[etree._Element] = []
    node: etree._Element | None = element
    while node is not None:
        chain.append(node)
        node = node.getparent()
    chain.reverse()
    decl = schema().elements.get(local_name(chain[0].tag))
    for step in chain[1:]:
        if decl is None:
            return None
        decl = child_declarations(decl).get(local_name(step.tag))
    return decl


def child_declarations(decl: Any) -> dict[str, Any]:
    """Child element declarations of an element declaration, by local name, in model order."""
    content = getattr(decl.type, "content", None)
    if content is None or not hasattr(content, "iter_elements"):
        return {}
    return {child.local_name: child for child in content.iter_elements()}


def _allowed_children(element: etree._Element) -> list[str]:
    decl = element_declaration(element)
    return list(child_declarations(decl)) if decl is not None else []


def _max_occurs(element: etree._Element, child: str) -> int | None:
    decl = element_declaration(element)
    found = child_declarations(decl).get(child) if decl is not None else None
    return getattr(found, "max_occurs", None)


def _xsd_element(error: Any) -> Any:
    elem = error.elem
    return element_declaration(elem) if isinstance(elem, etree._Element) else None


def _attribute_decl(error: Any, attr: str) -> Any:
    decl = _xsd_element(error)
    if decl is None:
        return None
    found = decl.attributes.get(attr)
    return getattr(found, "type", None)


def _allowed_attributes(error: Any) -> list[str]:
    decl = _xsd_element(error)
    return [str(name) for name in decl.attributes] if decl is not None else []


def _expectation(xsd_type: Any, reason: str) -> str:
    phrase = describe_type(xsd_type) if xsd_type is not None else None
    if phrase:
        return f"must be {phrase}"
    return reason.split(": ", 1)[-1].rstrip(".")


def describe_type(xsd_type: Any) -> str | None:
    """A short phrase for what a simple type accepts, for messages and editor hints."""
    if xsd_type is None:
        return None
    doc = _documentation(xsd_type)
    if doc:
        return doc
    enumeration = getattr(xsd_type, "enumeration", None)
    if enumeration:
        return "one of " + ", ".join(str(v) for v in enumeration)
    if xsd_type.is_list():
        item = xsd_type.item_type
        if getattr(item, "enumeration", None):
            return "values from " + ", ".join(str(v) for v in item.enumeration) + " separated by spaces"
        return f"values separated by spaces, each {describe_type(item)}"
    base = getattr(xsd_type, "primitive_type", None)
    base_name = local_name(getattr(base, "name", "") or "")
    low, high = getattr(xsd_type, "min_value", None), getattr(xsd_type, "max_value", None)
    if (
        base_name == "decimal"
        or base_name == "integer"
        or "int" in local_name(getattr(xsd_type.base_type, "name", "") or "")
    ):
        if low is not None and high is not None:
            return f"a whole number from {low} to {high}"
        if low is not None:
            return f"a whole number of at least {low}"
        return "a whole number"
    if base_name == "boolean":
        return "true or false"
    if base_name == "dateTime":
        return "a date and time such as 2024-05-01T12:00:00Z"
    base_type = getattr(xsd_type, "base_type", None)
    return describe_type(base_type) if base_type is not None and base_type is not xsd_type else None


def _documentation(component: Any) -> str | None:
    annotation = getattr(component, "annotation", None)
    if annotation is None or not annotation.documentation or getattr(component, "name", None) is None:
        return None
    text = str(annotation.documentation[0].text or "").strip()
    first = re.split(r"(?<=\.)\s", text, maxsplit=1)[0].rstrip(".")
    return first[:1].lower() + first[1:] if first else None
