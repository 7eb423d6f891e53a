"""The records mirror the XSD exactly: same attributes, same defaults, same required set, same children.

This is what keeps schemas/ the single source of truth: change one without the other and
this test names the difference.
"""

from __future__ import annotations

from dataclasses import MISSING
from typing import Any

import pytest

from ckmconf.binding import Record, plan
from ckmconf.model import Part, System
from ckmconf.schema import child_declarations, schema


def _pairs() -> list[tuple[str, type[Record], Any]]:
    """(path, record class, XSD element declaration) for every element kind reachable from the roots."""
    found: list[tuple[str, type[Record], Any]] = []
    seen: set[tuple[type[Record], int]] = set()
    todo: list[tuple[str, type[Record], Any]] = [
        ("/System", System, schema().elements["System"]),
        ("/Part", Part, schema().elements["Part"]),
    ]
    while todo:
        path, cls, decl = todo.pop()
        key = (cls, id(decl.type))
        if key in seen:
            continue
        seen.add(key)
        found.append((path, cls, decl))
        children = child_declarations(decl)
        for p in plan(cls):
            for tag, child_cls in p.classes.items():
                assert tag in children, f"{path}: record field {p.name} expects <{tag}>, which the XSD does not allow"
                todo.append((f"{path}/{tag}", child_cls, children[tag]))
    return found


PAIRS = _pairs()


def test_every_xsd_element_has_a_record() -> None:
    by_path = {path for path, _, _ in PAIRS}
    for path, cls, decl in PAIRS:
        covered = {tag for p in plan(cls) for tag in p.classes}
        for child in child_declarations(decl):
            assert child in covered, f"{path}: XSD child <{child}> has no record field in {cls.__name__}"
    assert len(by_path) > 60


@pytest.mark.parametrize("path,cls,decl", PAIRS, ids=[p for p, _, _ in PAIRS])
def test_attributes_match(path: str, cls: type[Record], decl: Any) -> None:
    fields = {p.xml: p for p in plan(cls) if p.kind == "attr"}
    xsd = {str(name): attribute for name, attribute in decl.attributes.items()}
    assert set(fields) == set(xsd), f"{path}: record {sorted(fields)} vs XSD {sorted(xsd)}"
    for name, attribute in xsd.items():
        field = fields[name]
        if attribute.use == "required":
            assert field.default is MISSING, f"{path}/@{name} is required in the XSD but has a default in the record"
        elif attribute.default is not None:
            assert field.default is not MISSING and field.parse is not None
            assert field.parse(attribute.default) == field.default, f"{path}/@{name}: XSD default {attribute.default!r}"
        else:
            assert field.default is None, f"{path}/@{name} is optional without default: the record must default to None"


def test_docstrings_name_their_element() -> None:
    for _, cls, _ in PAIRS:
        assert cls.__doc__ and (f"<{cls.TAG}>" in cls.__doc__ or cls.TAG in cls.__doc__), cls.__name__


def test_every_element_and_attribute_is_documented() -> None:
    # The editor shows xs:documentation as help text; nothing may be left unexplained at the top level.
    for path, _, decl in PAIRS:
        assert decl.annotation is not None or decl.type.annotation is not None, f"{path} has no documentation"
