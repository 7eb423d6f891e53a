"""A configuration split across files: the main file and every file it includes (``<Include href>``).

Each file is a :class:`Document`; they share one undo stack, so undo follows the order of the
edits whatever file they touched, and each file knows whether it is modified. Edits are made
through the workspace, which finds the element's file. Validation loads the whole system as the
runtime would — from a snapshot of every file's current text, unsaved edits included — and
reports each problem at its real file; a problem's xpath is resolved in that file's tree.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from PySide6.QtCore import QObject, QTimer, Signal
from PySide6.QtGui import QUndoStack

from ckmconf import load
from ckmconf.model import System
from ckmconf.source import NAMESPACE

from .document import Document, Element, Problem, _mission_problems, local, resolve


class Workspace(QObject):
    """The main file and its includes (see the module docstring)."""

    changed = Signal(object)
    structure_changed = Signal()
    problems_changed = Signal()
    modified_changed = Signal()

    def __init__(self, path: Path | None = None, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.undo = QUndoStack(self)
        self.main = self._adopt(Document(path.resolve() if path else None, parent=self, undo=self.undo))
        self.documents: dict[Path, Document] = {}
        self.problems: list[Problem] = []
        self.system: System | None = None  # as the files are now (None while they do not load)
        self.last_system: System | None = None  # the last that loaded (what is probably running)
        self._follow_includes(self.main)
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(150)
        self._timer.timeout.connect(self.validate)
        self.undo.indexChanged.connect(lambda _: self._timer.start())
        self.structure_changed.connect(lambda: self._follow_includes(self.main))

    def _adopt(self, document: Document) -> Document:
        document.changed.connect(self.changed)
        document.structure_changed.connect(self.structure_changed)
        document.modified_changed.connect(self.modified_changed)
        return document

    def _follow_includes(self, document: Document) -> None:
        """Open every file ``document`` includes (once each, as the loader does)."""
        if document.path is None:
            return
        for element in document.root:
            if not isinstance(element.tag, str) or local(element) != "Include" or not element.get("href"):
                continue
            target = (document.path.parent / element.get("href", "")).resolve()
            if target in self.documents or target == self.main.path or not target.is_file():
                continue
            try:
                included = self._adopt(Document(target, parent=self, undo=self.undo))
            except (OSError, ValueError):
                continue  # the loader reports an unreadable include at its <Include>
            self.documents[target] = included
            self._follow_includes(included)

    # ------------------------------------------------------------------ files

    def all(self) -> list[Document]:
        """The main file and the included files open here."""
        return [self.main, *self.documents.values()]

    def included(self, include: Element) -> Document | None:
        """The file an ``<Include>`` names, when it is open here."""
        owner = self.document_of(include)
        if owner is None or owner.path is None:
            return None
        return self.documents.get((owner.path.parent / include.get("href", "")).resolve())

    def document_of(self, element: Element) -> Document | None:
        """The file ``element`` belongs to, if open here."""
        root = element.getroottree().getroot()
        return next((d for d in self.all() if d.root is root), None)

    @property
    def modified(self) -> bool:
        """Whether any file has unsaved edits."""
        return any(d.modified for d in self.all())

    def save_all(self) -> list[Path]:
        """Write the modified files only: an untouched file keeps its bytes (its own line breaks
        inside tags, which no XML parser keeps, included); a written one is re-serialised."""
        return [
            d.save()
            for d in self.all()
            if d.modified or (d is self.main and d.path is not None and not d.path.exists())
        ]

    # ------------------------------------------------------------------ edits (through the element's file)

    def _doc(self, element: Element) -> Document:
        document = self.document_of(element)
        if document is None:
            raise ValueError(f"element {local(element)} is not in this workspace")
        return document

    def set_attribute(self, element: Element, name: str, value: str | None) -> None:
        """Set an attribute in the file that holds ``element`` (undoable)."""
        self._doc(element).set_attribute(element, name, value)

    def set_text(self, element: Element, text: str) -> None:
        """Set the text of ``element`` in the file that holds it (undoable)."""
        self._doc(element).set_text(element, text)

    def insert(self, parent: Element, index: int, element: Element) -> None:
        """Insert ``element`` under ``parent`` in the file that holds it (undoable)."""
        self._doc(parent).insert(parent, index, element)

    def remove(self, element: Element) -> None:
        """Remove ``element`` from the file that holds it (undoable)."""
        self._doc(element).remove(element)

    def new_element(self, tag: str, attributes: dict[str, str] | None = None) -> Element:
        """A new element of the CKM namespace, not inserted yet."""
        return self.main.new_element(tag, attributes)

    # ------------------------------------------------------------------ queries

    def elements(self, tag: str) -> list[Element]:
        """Every element ``tag`` across the open files."""
        return [e for d in self.all() for e in d.root.iter(f"{{{NAMESPACE}}}{tag}")]

    def mission(self, name: str) -> Element | None:
        """The ``Mission`` named ``name`` in any open file, if any."""
        return next((m for m in self.elements("Mission") if m.get("name") == name), None)

    # ------------------------------------------------------------------ validation

    def validate(self) -> list[Problem]:
        """Load the system from a snapshot of every file as edited now; problems at their real files."""
        with tempfile.TemporaryDirectory(prefix="ckm-editor-") as scratch:
            base = self._common_base()
            copies: dict[str, str] = {}
            for document in self.all():
                relative = document.path.relative_to(base) if document.path else Path("untitled.xml")
                copy = Path(scratch) / relative
                copy.parent.mkdir(parents=True, exist_ok=True)
                copy.write_bytes(document.to_bytes())
                copies[str(copy)] = str(document.path) if document.path else "untitled.xml"
            main = Path(scratch) / (self.main.path.relative_to(base) if self.main.path else Path("untitled.xml"))
            result = load(main, strict=False)

            def real(file: str) -> str:
                return copies.get(file, file.replace(scratch, str(base)))

            problems = [Problem(real(e.file), e.line, e.column, e.xpath, e.message) for e in result.errors]
            self.system = result.system
            self.last_system = result.system or self.last_system
            if result.system is not None and not result.errors:
                problems += [
                    Problem(real(p.file), p.line, p.column, p.xpath, p.message, p.severity, p.source)
                    for p in _mission_problems(result.system)
                ]
        self.problems = problems
        self.problems_changed.emit()
        return problems

    def _common_base(self) -> Path:
        paths = [d.path for d in self.all() if d.path is not None]
        if not paths:
            return Path(".")
        base = paths[0].parent
        while not all(p.is_relative_to(base) for p in paths):
            base = base.parent
        return base

    def find(self, problem: Problem) -> Element | None:
        """The element a problem names, in the file it is reported in."""
        document = next((d for d in self.all() if d.path is not None and str(d.path) == problem.file), self.main)
        return resolve(document.root, problem.xpath)
