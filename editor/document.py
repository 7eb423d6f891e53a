"""The edited configuration: an lxml tree, undoable commands, saving, and live validation.

The tree *is* the model: the editor works on the XML itself, element by element, so every
element the XSD allows is editable with no editor code for it, and a file opened and saved
without edits is written back byte for byte. Every change goes through a :class:`QUndoCommand`
on :attr:`Document.undo`, so every edit can be undone; new elements get the indentation of their
siblings so saved files stay diff-friendly.

Validation runs the lax ckmconf loader on the serialised tree (its path anchors the includes),
then the static mission checks and the plans' wait-for graph checks when the system loads; all
give located problems. It runs a
moment after the last edit (debounced), which keeps typing responsive on the use case.
"""

from __future__ import annotations

import abc
import copy
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from lxml import etree
from PySide6.QtCore import QObject, QTimer, Signal
from PySide6.QtGui import QUndoCommand, QUndoStack

from ckmconf import load_bytes
from ckmconf.model import System
from ckmconf.source import NAMESPACE

NS = NAMESPACE  # the model's one namespace, as ckmconf reads it
Element = etree._Element


def qname(tag: str) -> str:
    """``tag`` in the CKM configuration namespace, as lxml spells it."""
    return f"{{{NS}}}{tag}"


def local(element: Element) -> str:
    """The tag of ``element`` without its namespace."""
    return etree.QName(element).localname


@dataclass(frozen=True)
class Problem:
    """One problem the panel lists; ``element`` is where a click goes (None when not found)."""

    file: str
    line: int
    column: int
    xpath: str
    message: str
    severity: str = "error"
    source: str = "config"  # "config" (ckmconf), "mission" (off-line checks) or "plan" (wait-for graph)

    def text(self) -> str:
        """``file:line: message``, as the problems panel shows it."""
        return f"{Path(self.file).name}:{self.line}: {self.message}"


class Document(QObject):
    """One configuration file being edited."""

    changed = Signal(object)  # the element that changed (or the root)
    structure_changed = Signal()  # elements added or removed
    problems_changed = Signal()
    path_changed = Signal()
    modified_changed = Signal()

    def __init__(
        self,
        path: Path | None = None,
        text: bytes | None = None,
        parent: QObject | None = None,
        undo: QUndoStack | None = None,
    ) -> None:
        super().__init__(parent)
        self.path = path
        self.undo = undo if undo is not None else QUndoStack(self)  # shared by a workspace's files
        self.edits = 0  # commands applied to this file, net of undos: modified while ≠ the saved count
        self.saved_edits = 0
        parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, remove_comments=False)
        data = text if text is not None else path.read_bytes() if path is not None else _EMPTY
        self.tree: etree._ElementTree = etree.ElementTree(etree.fromstring(data, parser))
        # The declaration is written back as it was (lxml would requote it): an unedited file
        # saves byte for byte.
        text_data = data.lstrip(b"\xef\xbb\xbf")
        declaration = re.match(rb"<\?xml[^>]*\?>", text_data)
        self.declaration = declaration.group(0) if declaration else DECLARATION
        # So is the prolog (the comments before the root, with their line breaks).
        start = declaration.end() if declaration else 0
        root_at = re.compile(rb"<(?![!?])").search(text_data, _after_comments(text_data, start))
        self.prolog = text_data[start : root_at.start()] if root_at else b"\n"
        self.problems: list[Problem] = []
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(150)
        self._timer.timeout.connect(self.validate)
        self.undo.indexChanged.connect(lambda _: self._timer.start())

    # ------------------------------------------------------------------ content

    @property
    def root(self) -> Element:
        """The root element of the file."""
        return self.tree.getroot()

    def to_bytes(self) -> bytes:
        """The file as written: its XML declaration and prolog kept, ending with a newline."""
        body: bytes = etree.tostring(self.root, encoding="UTF-8", with_tail=False)
        data = self.declaration + self.prolog + body
        return data if data.endswith(b"\n") else data + b"\n"

    def save(self, path: Path | None = None) -> Path:
        """Write the file to ``path`` (default: where it came from) and mark it unmodified.

        Returns:
            The path written.

        Raises:
            ValueError: the document has no file name yet and ``path`` is None.
        """
        target = path or self.path
        if target is None:
            raise ValueError("no file name: use save as")
        target.write_bytes(self.to_bytes())
        if target != self.path:
            self.path = target
            self.path_changed.emit()
        self.saved_edits = self.edits
        self.modified_changed.emit()
        return target

    @property
    def modified(self) -> bool:
        """Whether the file has edits not saved."""
        return self.edits != self.saved_edits

    def count(self, step: int) -> None:
        """A command was applied (+1) or undone (−1) on this file."""
        self.edits += step
        self.modified_changed.emit()

    # ------------------------------------------------------------------ edits (all undoable)

    def set_attribute(self, element: Element, name: str, value: str | None) -> None:
        """Set (or, with None, remove) attribute ``name`` of ``element`` as an undoable command."""
        if element.get(name) != value:
            self.undo.push(SetAttribute(self, element, name, value))

    def set_text(self, element: Element, text: str) -> None:
        """Set the text of ``element`` as an undoable command."""
        if (element.text or "") != text:
            self.undo.push(SetText(self, element, text))

    def insert(self, parent: Element, index: int, element: Element) -> None:
        """Insert ``element`` under ``parent`` at ``index`` as an undoable command."""
        self.undo.push(InsertElement(self, parent, index, element))

    def remove(self, element: Element) -> None:
        """Remove ``element`` from its parent as an undoable command."""
        if element.getparent() is not None:
            self.undo.push(RemoveElement(self, element))

    def new_element(self, tag: str, attributes: dict[str, str] | None = None) -> Element:
        """A new element ``tag`` of the CKM namespace with ``attributes`` (not inserted yet)."""
        element = etree.Element(qname(tag), nsmap=None)
        for key, value in (attributes or {}).items():
            element.set(key, value)
        return element

    # ------------------------------------------------------------------ validation

    def validate(self) -> list[Problem]:
        """Lax load of the current tree, then the static mission checks; emits problems_changed."""
        name = str(self.path) if self.path is not None else "untitled.xml"
        result = load_bytes(self.to_bytes(), name, strict=False)
        problems = [Problem(e.file, e.line, e.column, e.xpath, e.message) for e in result.errors]
        if result.system is not None and not result.errors:
            problems += _mission_problems(result.system)
        self.problems = problems
        self.problems_changed.emit()
        return problems

    def find(self, xpath: str) -> Element | None:
        """The element a problem's readable xpath (``/System[@name='x']/Node[@name='n']/@attr``) names."""
        return resolve(self.root, xpath)


def _after_comments(data: bytes, start: int) -> int:
    """The offset after the comments and processing instructions that follow ``start``."""
    position = start
    while True:
        match = re.compile(rb"\s*(<!--.*?-->|<\?.*?\?>)", re.S).match(data, position)
        if match is None:
            return position
        position = match.end()


def _mission_problems(system: System) -> list[Problem]:
    # Loaded on first use: the validation brings networkx, which opening the editor does not need.
    from runtime.missions.validation.check import check_missions, check_plans

    found: list[Problem] = []
    for f in check_missions(system):  # each top mission's static checks and SRFlowGen
        found.append(Problem(f.file, f.line, f.column, f.xpath, f"[{f.kind}] {f.message}", f.severity, "mission"))
    for f in check_plans(system):  # the plans' wait-for graphs (deadlocks …)
        found.append(Problem(f.file, f.line, f.column, f.xpath, f"[{f.kind}] {f.message}", f.severity, "plan"))
    return list(dict.fromkeys(found))


_STEP = re.compile(r"^(?P<tag>[A-Za-z_][\w.-]*)(?:\[(?:@(?P<attr>[\w.-]+)='(?P<value>[^']*)'|(?P<index>\d+))\])?$")


def resolve(root: Element, xpath: str) -> Element | None:
    """Follow ``/Tag[@attr='v']/Tag[2]/…`` from the root; attribute and unknown steps stop the walk."""
    steps = [s for s in xpath.split("/") if s]
    if not steps:
        return root
    current: Element | None = None
    for number, step in enumerate(steps):
        if step.startswith("@"):
            break
        match = _STEP.match(step)
        if match is None:
            break
        parent = current if current is not None else root
        candidates = [root] if number == 0 else [c for c in parent if isinstance(c.tag, str)]
        candidates = [c for c in candidates if local(c) == match["tag"]]
        if match["attr"]:
            candidates = [c for c in candidates if c.get(match["attr"]) == match["value"]]
        elif match["index"]:
            index = int(match["index"]) - 1
            candidates = candidates[index : index + 1]
        if not candidates:
            break
        current = candidates[0]
    return current


# ---------------------------------------------------------------------- commands


def _indent_like_siblings(parent: Element, index: int, element: Element) -> None:
    """Whitespace so the new element sits on its own line at its siblings' depth."""
    depth = len(list(parent.iterancestors())) + 1
    inner = "\n" + "  " * depth
    children = list(parent)
    if not children:
        parent.text = inner
        element.tail = "\n" + "  " * (depth - 1)
        return
    if index >= len(children):
        last = children[-1]
        element.tail = last.tail
        last.tail = inner
    else:
        element.tail = inner


class _Command(QUndoCommand):
    """Counts itself on its file, so each file of a workspace knows whether it is modified."""

    def __init__(self, document: Document, text: str) -> None:
        super().__init__(text)
        self.document = document

    def redo(self) -> None:
        self.apply()
        self.document.count(+1)

    def undo(self) -> None:
        self.revert()
        self.document.count(-1)

    @abc.abstractmethod
    def apply(self) -> None:
        """Make the edit (redo)."""

    @abc.abstractmethod
    def revert(self) -> None:
        """Take it back (undo)."""


class SetAttribute(_Command):
    """Undoable edit of one attribute (None removes it)."""

    def __init__(self, document: Document, element: Element, name: str, value: str | None) -> None:
        super().__init__(document, f"set {local(element)}/@{name}")
        self.element, self.name, self.value, self.old = element, name, value, element.get(name)

    def _apply(self, value: str | None) -> None:
        if value is None:
            if self.name in self.element.attrib:
                del self.element.attrib[self.name]
        else:
            self.element.set(self.name, value)
        self.document.changed.emit(self.element)

    def apply(self) -> None:
        """Set the new value."""
        self._apply(self.value)

    def revert(self) -> None:
        """Restore the old value."""
        self._apply(self.old)


class SetText(_Command):
    """Undoable edit of an element's text."""

    def __init__(self, document: Document, element: Element, text: str) -> None:
        super().__init__(document, f"edit {local(element)} text")
        self.element, self.new, self.old = element, text, element.text

    def apply(self) -> None:
        """Set the new text."""
        self.element.text = self.new
        self.document.changed.emit(self.element)

    def revert(self) -> None:
        """Restore the old text."""
        self.element.text = self.old
        self.document.changed.emit(self.element)


class InsertElement(_Command):
    """Undoable insertion of an element, indented like its siblings."""

    def __init__(self, document: Document, parent: Element, index: int, element: Element) -> None:
        super().__init__(document, f"add {local(element)}")
        self.parent, self.index, self.element = parent, index, element
        self._tails: tuple[str | None, str | None, str | None] | None = None

    def apply(self) -> None:
        """Insert the element, indented like its siblings."""
        children = list(self.parent)
        last = children[-1] if children else None
        self._tails = (self.parent.text, last.tail if last is not None else None, self.element.tail)
        _indent_like_siblings(self.parent, self.index, self.element)
        self.parent.insert(self.index, self.element)
        self.document.structure_changed.emit()

    def revert(self) -> None:
        """Remove the element and restore the whitespace around it."""
        self.parent.remove(self.element)
        if self._tails is not None:
            text, last_tail, own = self._tails
            self.parent.text = text
            children = list(self.parent)
            if children and self.index >= len(children):
                children[-1].tail = last_tail
            self.element.tail = own
        self.document.structure_changed.emit()


class RemoveElement(_Command):
    """Undoable removal of an element."""

    def __init__(self, document: Document, element: Element) -> None:
        super().__init__(document, f"remove {local(element)}")
        parent = element.getparent()
        assert parent is not None
        self.parent, self.element = parent, element
        self.index = list(parent).index(element)
        self._previous_tail: str | None = None

    def apply(self) -> None:
        """Remove the element; the closing tag keeps its indentation."""
        previous = self.element.getprevious()
        if previous is not None and self.index == len(self.parent) - 1:
            self._previous_tail = previous.tail
            previous.tail = self.element.tail  # the closing tag keeps its indentation
        self.parent.remove(self.element)
        self.document.structure_changed.emit()

    def revert(self) -> None:
        """Put the element back where it was."""
        self.parent.insert(self.index, self.element)
        previous = self.element.getprevious()
        if previous is not None and self._previous_tail is not None:
            previous.tail = self._previous_tail
        self.document.structure_changed.emit()


def duplicate(element: Element) -> Element:
    """A deep copy, for copy/paste."""
    return copy.deepcopy(element)


DECLARATION = b'<?xml version="1.0" encoding="UTF-8"?>'
_EMPTY = DECLARATION + f'\n<System xmlns="{NAMESPACE}" version="1.0" name="untitled"/>\n'.encode()

Listener = Callable[[Element], None]
