"""Every attribute, element and named type of the XSD model explains itself.

The configuration editor shows xs:documentation as help text, so an attribute that leans only
on its type's documentation ("a duration in seconds…") tells a user nothing about what the value
is for. Each attribute therefore carries documentation of its own, and so does every element
declaration and every named type; the tests list everything missing in one failure.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from ckmconf.schema import ROOTS, child_declarations, schema


def _own_documentation(component: Any) -> str:
    """The component's own xs:documentation text (not its type's), stripped; empty when it has none."""
    annotation = getattr(component, "annotation", None)
    if annotation is None:
        return ""
    return " ".join(str(doc.text or "").strip() for doc in annotation.documentation).strip()


def _declarations() -> Iterator[tuple[str, Any]]:
    """(path, element declaration) for every element reachable from the roots, each declaration once."""
    seen: set[int] = set()
    todo: list[tuple[str, Any]] = [(f"/{root}", schema().elements[root]) for root in ROOTS]
    while todo:
        path, decl = todo.pop(0)
        if id(decl) in seen:
            continue
        seen.add(id(decl))
        yield path, decl
        todo.extend((f"{path}/{name}", child) for name, child in child_declarations(decl).items())


DECLARATIONS = list(_declarations())


def test_the_walk_reaches_the_whole_model() -> None:
    paths = {path for path, _ in DECLARATIONS}
    # Declarations shared by several parents (the content of System and Part, the 2D atoms of
    # Geometry2D and Prism) are visited once, under the first path that reaches them.
    expected = {"/Part", "/System/Node/Monitor/Alarm", "/System/Environment/Object/Geometry3D/Prism"}
    assert expected <= paths
    assert "/System/Environment/Object/Geometry2D/Circle" in paths
    assert len(DECLARATIONS) > 90


def test_every_attribute_has_its_own_documentation() -> None:
    missing = [
        f"{path}/@{name}"
        for path, decl in DECLARATIONS
        for name, attribute in decl.attributes.items()
        if not _own_documentation(attribute)
    ]
    assert not missing, f"{len(missing)} attributes have no documentation of their own:\n" + "\n".join(missing)


def test_every_element_declaration_has_its_own_documentation() -> None:
    missing = [path for path, decl in DECLARATIONS if not _own_documentation(decl)]
    assert not missing, f"{len(missing)} elements have no documentation of their own:\n" + "\n".join(missing)


def test_every_named_type_has_documentation() -> None:
    missing = [str(name) for name, xsd_type in schema().types.items() if not _own_documentation(xsd_type)]
    assert not missing, f"{len(missing)} named types have no documentation:\n" + "\n".join(sorted(missing))
