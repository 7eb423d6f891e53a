"""The editor's view of the CKM schema: forms, allowed children and checks, read from ``schemas/``.

Nothing here names a CKM element: everything is read at run time from the XSD through
xmlschema, so an element or attribute added to the schema becomes editable with no editor
change. Only System and Part are global elements; every other element is local to a complex
type, and one tag may mean different things under different parents (``Service`` in a
SmartResource is a full service, in a CompositionMatrix a bare reference), so lookups take the
parent, and the grandparent when even the parent is ambiguous.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import xmlschema
from xmlschema.validators.models import ModelVisitor

from ckmconf import schema as ckm_schema

from .values import AttributeSpec, Kind, check, documentation, placeholder, type_name, value_spec

__all__ = ["AttributeSpec", "ChildSpec", "ElementSpec", "Kind", "SchemaModel"]


@dataclass(frozen=True)
class ChildSpec:
    """A child element the content model allows, with its overall occurrence bounds.

    ``max_occurs`` is None when unbounded. A child in a choice has ``min_occurs`` 0 and lists
    the other branches in ``alternatives`` (one of them may be required).
    """

    tag: str
    min_occurs: int
    max_occurs: int | None
    documentation: str
    alternatives: tuple[str, ...] = ()


@dataclass(frozen=True)
class ElementSpec:
    """Everything a form needs about one element: help, attributes, children and text content."""

    tag: str
    documentation: str
    type_name: str
    attributes: tuple[AttributeSpec, ...]
    children: tuple[ChildSpec, ...]
    text: AttributeSpec | None = None

    @property
    def has_text(self) -> bool:
        """Whether the element holds a value as text (simple content, such as a matrix Row)."""
        return self.text is not None

    @property
    def text_kind(self) -> Kind | None:
        """The kind of the element's text content, or None when it holds no text."""
        return self.text.kind if self.text is not None else None

    def attribute(self, name: str) -> AttributeSpec:
        """The spec of attribute ``name``.

        Raises:
            KeyError: the element has no such attribute (the message lists the allowed ones).
        """
        for spec in self.attributes:
            if spec.name == name:
                return spec
        raise KeyError(f"{self.tag} has no attribute {name!r} (allowed: {', '.join(self.attribute_names())})")

    def attribute_names(self) -> list[str]:
        """The names of the element's attributes, in schema order."""
        return [spec.name for spec in self.attributes]

    def child(self, tag: str) -> ChildSpec:
        """The spec of child element ``tag``.

        Raises:
            KeyError: the content model allows no such child.
        """
        for spec in self.children:
            if spec.tag == tag:
                return spec
        raise KeyError(f"{self.tag} takes no child {tag!r}")


class SchemaModel:
    """Introspection of a CKM schema for the editor (pure Python, no Qt)."""

    def __init__(self, xsd: xmlschema.XMLSchemaBase) -> None:
        self.xsd = xsd
        self.namespace = str(xsd.target_namespace)
        self._parents: dict[int, list[Any]] = {}  # id(declaration) -> declarations holding it
        self._by_tag: dict[str, list[Any]] = {}  # tag -> distinct declarations, global ones first
        self._specs: dict[tuple[int, bool], ElementSpec] = {}
        stack = list(xsd.elements.values())
        for decl in stack:
            self._by_tag.setdefault(decl.local_name, []).append(decl)
        seen = {id(decl) for decl in stack}
        while stack:
            decl = stack.pop()
            for child in _child_declarations(decl):
                holders = self._parents.setdefault(id(child), [])
                if not any(holder is decl for holder in holders):
                    holders.append(decl)
                if id(child) not in seen:
                    seen.add(id(child))
                    self._by_tag.setdefault(child.local_name, []).append(child)
                    stack.append(child)

    @classmethod
    def load(cls, schemas_dir: Path | None = None) -> SchemaModel:
        """The model of ``schemas_dir/ckm.xsd`` (default: the schema ckmconf validates with), cached."""
        default = ckm_schema.schema_dir().resolve()
        return _load(None if schemas_dir is None or schemas_dir.resolve() == default else schemas_dir.resolve())

    # ------------------------------------------------------------ elements

    def roots(self) -> list[str]:
        """The elements a document may start with (System, Part)."""
        return [str(name) for name in self.xsd.elements]

    def tags(self) -> list[str]:
        """Every element tag the schema declares, sorted."""
        return sorted(self._by_tag)

    def element(self, tag: str, parent: str | None = None, *, grandparent: str | None = None) -> ElementSpec:
        """The spec of ``tag`` as a child of ``parent`` (None: a root, or any if all are alike)."""
        decl, merged = self._resolve(tag, parent, grandparent)
        return self._spec(decl, merged)

    def element_at(self, path: Sequence[str]) -> ElementSpec:
        """The spec of the element at ``path`` of tags from the root, such as ("System", "Node")."""
        return self._spec(self._at(path), False)

    # ------------------------------------------------------------ children

    def allowed_children(
        self, parent_tag: str, existing: Sequence[str], grandparent: str | None = None
    ) -> list[ChildSpec]:
        """The children "Add child" may offer now: those that still fit somewhere in ``existing``."""
        decl, _ = self._resolve(parent_tag, grandparent, None, existing)
        spec = self._spec(decl, False)
        return [child for child in spec.children if self._insertion(decl, spec, existing, child) is not None]

    def child_position(
        self, parent_tag: str, existing: Sequence[str], new_tag: str, grandparent: str | None = None
    ) -> int:
        """Where ``new_tag`` goes among ``existing`` so the content model's order holds.

        The last such place, so a new child follows its same-tag siblings; when no place is
        valid (the child is over its maximum, or ``existing`` is already out of order) the place
        the declaration order suggests.
        """
        decl, _ = self._resolve(parent_tag, grandparent, None, [*existing, new_tag])
        spec = self._spec(decl, False)
        child = spec.child(new_tag)
        found = self._insertion(decl, spec, existing, child)
        return found if found is not None else _order_guess(spec, existing, new_tag)

    # ------------------------------------------------------------ values

    def check_value(
        self, tag: str, attribute: str, text: str, parent: str | None = None, *, grandparent: str | None = None
    ) -> str | None:
        """None when ``text`` is a valid value of the attribute, else the reason, worded for people."""
        decl, merged = self._resolve(tag, parent, grandparent)
        spec = self._spec(decl, merged)
        xsd_attribute = decl.attributes.get(attribute)
        if xsd_attribute is None:
            return f"{tag} has no attribute {attribute!r} (allowed: {', '.join(spec.attribute_names())})"
        return check(spec.attribute(attribute), xsd_attribute.type, text)

    def check_text(
        self, tag: str, text: str, parent: str | None = None, *, grandparent: str | None = None
    ) -> str | None:
        """None when ``text`` is valid content of a simple-content element, else the reason."""
        decl, merged = self._resolve(tag, parent, grandparent)
        spec = self._spec(decl, merged)
        if spec.text is None:
            return f"{tag} holds no text" if text.strip() else None
        return check(spec.text, decl.type.simple_type, text)

    def default_attributes(
        self, tag: str, parent: str | None = None, *, grandparent: str | None = None
    ) -> dict[str, str]:
        """The required attributes of a new ``tag``, each with a value the schema accepts if one is found."""
        decl, merged = self._resolve(tag, parent, grandparent)
        spec = self._spec(decl, merged)
        return {a.name: placeholder(a, decl.attributes[a.name].type, tag) for a in spec.attributes if a.required}

    def default_text(self, tag: str, parent: str | None = None, *, grandparent: str | None = None) -> str | None:
        """Initial text of a new simple-content element (None when it holds no text)."""
        decl, merged = self._resolve(tag, parent, grandparent)
        spec = self._spec(decl, merged)
        return placeholder(spec.text, decl.type.simple_type, tag) if spec.text is not None else None

    # ------------------------------------------------------------ internals

    def _resolve(
        self, tag: str, parent: str | None, grandparent: str | None, holding: Sequence[str] = ()
    ) -> tuple[Any, bool]:
        """The declaration of ``tag`` in this context, and whether it stands for several alike ones.

        Declarations that cannot hold the ``holding`` children are set aside, so a parent whose
        own parent is unknown is still found when its children tell which one it is.
        """
        decls = self._by_tag.get(tag)
        if not decls:
            raise KeyError(f"the schema declares no element {tag!r}")
        if parent is not None:
            decls = [
                d for d in decls if any(self._matches(p, parent, grandparent) for p in self._parents.get(id(d), []))
            ]
            if not decls:
                where = f"{parent!r}" + (f" inside {grandparent!r}" if grandparent else "")
                raise KeyError(f"{tag!r} is not a child of {where} in the schema")
        if len(decls) == 1:
            return decls[0], False
        if len({id(d.type) for d in decls}) == 1:
            return decls[0], True
        able = [d for d in decls if set(holding) <= {c.local_name for c in _child_declarations(d)}]
        if holding and len({id(d.type) for d in able}) == 1:
            return able[0], len(able) > 1
        holders = sorted({p.local_name for d in decls for p in self._parents.get(id(d), [])})
        hint = "its grandparent" if parent is not None else "its parent"
        raise KeyError(f"{tag!r} is declared differently under {', '.join(holders)}: name {hint}")

    def _matches(self, decl: Any, name: str, parent: str | None) -> bool:
        if decl.local_name != name:
            return False
        return parent is None or any(p.local_name == parent for p in self._parents.get(id(decl), []))

    def _at(self, path: Sequence[str]) -> Any:
        if not path or path[0] not in self.xsd.elements:
            raise KeyError(f"a path starts at a root element ({', '.join(self.roots())}), not {list(path)!r}")
        decl = self.xsd.elements[path[0]]
        for depth, tag in enumerate(path[1:], start=1):
            found = next((c for c in _child_declarations(decl) if c.local_name == tag), None)
            if found is None:
                raise KeyError(f"{'/'.join(path[:depth])} has no child {tag!r} in the schema")
            decl = found
        return decl

    def _spec(self, decl: Any, merged: bool) -> ElementSpec:
        key = (id(decl), merged)
        if key not in self._specs:
            self._specs[key] = _element_spec(decl, merged)
        return self._specs[key]

    def _insertion(self, decl: Any, spec: ElementSpec, existing: Sequence[str], child: ChildSpec) -> int | None:
        """The last index where ``child`` can be inserted without breaking the content model."""
        if child.max_occurs is not None and sum(1 for t in existing if t == child.tag) >= child.max_occurs:
            return None
        group = decl.type.model_group
        qualify = self._qualify
        tags = [qualify(t) for t in existing]
        guess = _order_guess(spec, existing, child.tag)
        if not _fits(group, tags):  # already broken: only the declaration order can guide us
            return guess if _fits(group, [qualify(child.tag)]) else None
        new = qualify(child.tag)
        order: list[int] = list(dict.fromkeys([len(tags), guess, *range(len(tags) - 1, -1, -1)]))
        for index in order:
            if _fits(group, [*tags[:index], new, *tags[index:]]):
                return index
        return None

    def _qualify(self, tag: str) -> str:
        return f"{{{self.namespace}}}{tag}" if self.namespace else tag


@cache
def _load(schemas_dir: Path | None) -> SchemaModel:
    if schemas_dir is None:
        return SchemaModel(ckm_schema.schema())
    return SchemaModel(xmlschema.XMLSchema10(str(schemas_dir / "ckm.xsd"), allow="sandbox", defuse="always"))


def _child_declarations(decl: Any) -> list[Any]:
    return _child_declarations_of(getattr(decl.type, "model_group", None))


def _element_spec(decl: Any, merged: bool) -> ElementSpec:
    xsd_type = decl.type
    own, of_type = documentation(decl), documentation(xsd_type)
    attributes = tuple(
        value_spec(
            str(name),
            attribute.type,
            required=attribute.use == "required",
            default=attribute.default,
            fixed=attribute.fixed,
            doc=documentation(attribute),
        )
        for name, attribute in decl.attributes.items()
        if isinstance(name, str)  # skips attribute wildcards
    )
    text = None
    if xsd_type.has_simple_content():
        simple = xsd_type.simple_type
        text = value_spec(
            "", simple, required=not simple.is_emptiable(), default=decl.default, doc=documentation(simple)
        )
    return ElementSpec(
        tag=str(decl.local_name),
        documentation=(of_type or own) if merged else (own or of_type),
        type_name=type_name(xsd_type) if xsd_type.name else "",
        attributes=attributes,
        children=_children(xsd_type.model_group),
        text=text,
    )


def _children(group: Any) -> tuple[ChildSpec, ...]:
    if group is None:
        return ()
    specs: dict[str, ChildSpec] = {}
    for child in _child_declarations_of(group):
        if child.local_name in specs:
            continue
        holder: Any = getattr(child, "parent", None)
        choice = getattr(holder, "model", None) == "choice"
        alternatives = tuple(str(e.local_name) for e in holder.iter_elements() if e is not child) if choice else ()
        specs[child.local_name] = ChildSpec(
            tag=str(child.local_name),
            min_occurs=0 if alternatives else int(group.overall_min_occurs(child)),
            max_occurs=group.overall_max_occurs(child),
            documentation=documentation(child) or documentation(child.type),
            alternatives=alternatives,
        )
    return tuple(specs.values())


def _child_declarations_of(group: Any) -> list[Any]:
    if group is None:
        return []
    return [e for e in group.iter_elements() if isinstance(e, xmlschema.XsdElement)]


def _order_guess(spec: ElementSpec, existing: Sequence[str], tag: str) -> int:
    """Just after the last existing child declared no later than ``tag``."""
    rank = {child.tag: index for index, child in enumerate(spec.children)}
    mine = rank.get(tag, len(rank))
    return max((i + 1 for i, t in enumerate(existing) if rank.get(t, -1) <= mine), default=0)


def _fits(group: Any, tags: Sequence[str]) -> bool:
    """Whether ``tags`` can be completed into valid content by adding children only.

    xmlschema's own model visitor walks the content; the occurrences it reports as missing are
    ignored (the user adds them later), those over a maximum and children left unmatched are not.
    """
    if group is None:
        return not tags
    model = ModelVisitor(group)
    for tag in tags:
        while model.element is not None:
            matched = model.match_element(tag) is not None
            for particle, occurs, _expected in model.advance(matched):
                if particle.max_occurs is not None and occurs > particle.max_occurs:
                    return False
            if matched:
                break
        else:
            return False
    return True
