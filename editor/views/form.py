"""The attribute form of the selected element, built from the XSD at run time.

One row per attribute the schema declares, in schema order: a list for enumerations and
booleans, a line edit otherwise (its placeholder shows the default), the documentation as the
tooltip and the element's documentation on top. A value is checked by the schema
(:meth:`SchemaModel.check_value`) when it is committed; a refused value is not applied — the
row goes back to the current value and the reason is shown under the form.
"""

from __future__ import annotations

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QComboBox,
    QFormLayout,
    QLabel,
    QLineEdit,
    QVBoxLayout,
    QWidget,
)

from ..document import Element, local
from ..model.schema import AttributeSpec, SchemaModel
from ..workspace import Workspace
from .tree import parent_tag

UNSET = "(not set)"


class AttributeForm(QWidget):
    """Edits the attributes (and text) of one element (see the module docstring)."""

    refused = Signal(str)

    def __init__(self, document: Workspace, schema: SchemaModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.document, self.schema = document, schema
        self.element: Element | None = None
        self.title = QLabel()
        self.title.setStyleSheet("font-weight: bold; font-size: 13px")
        self.help = QLabel()
        self.help.setWordWrap(True)
        self.help.setStyleSheet("color: #555")
        self.rows = QFormLayout()
        self.error = QLabel()
        self.error.setWordWrap(True)
        self.error.setStyleSheet("color: #c62828")
        layout = QVBoxLayout(self)
        layout.addWidget(self.title)
        layout.addWidget(self.help)
        layout.addLayout(self.rows)
        layout.addWidget(self.error)
        layout.addStretch(1)
        self.editors: dict[str, QLineEdit | QComboBox] = {}
        document.changed.connect(self._changed)

    def show_element(self, element: Element | None) -> None:
        """Rebuild the form for ``element``'s attributes and text (empty for None)."""
        self.element = element
        self.error.clear()
        while self.rows.rowCount():
            self.rows.removeRow(0)
        self.editors = {}
        if element is None:
            self.title.clear()
            self.help.clear()
            return
        tag = local(element)
        self.title.setText(tag)
        try:
            spec = self.schema.element(tag, parent_tag(element))
        except KeyError as exc:
            self.help.setText(str(exc))
            return
        self.help.setText(spec.documentation)
        for attribute in spec.attributes:
            editor = self._editor(element, attribute)
            name = QLabel(attribute.name + (" *" if attribute.required else ""))
            name.setToolTip(attribute.documentation)
            self.rows.addRow(name, editor)
            self.editors[attribute.name] = editor
        if spec.has_text:
            text = QLineEdit(element.text or "")
            text.setToolTip("The element's text content.")
            text.editingFinished.connect(lambda: self._commit_text(text))
            self.rows.addRow(QLabel("(text)"), text)
            self.editors["#text"] = text

    def _editor(self, element: Element, attribute: AttributeSpec) -> QLineEdit | QComboBox:
        current = element.get(attribute.name)
        choices = list(attribute.enumeration) or (["true", "false"] if attribute.kind == "bool" else [])
        if choices:
            box = QComboBox()
            box.addItems(([] if attribute.required else [UNSET]) + choices)
            box.setCurrentText(current if current is not None else UNSET if not attribute.required else choices[0])
            box.setToolTip(attribute.documentation)
            box.activated.connect(lambda _i, a=attribute, b=box: self.commit(a.name, b.currentText()))
            return box
        line = QLineEdit(current or "")
        if attribute.default is not None:
            line.setPlaceholderText(attribute.default)
        line.setToolTip(attribute.documentation)
        line.editingFinished.connect(lambda a=attribute, e=line: self.commit(a.name, e.text()))
        return line

    # ------------------------------------------------------------------ committing

    def commit(self, name: str, text: str) -> bool:
        """Apply ``text`` to attribute ``name`` if the schema accepts it; else show why and revert."""
        element = self.element
        if element is None:
            return False
        spec = next(a for a in self.schema.element(local(element), parent_tag(element)).attributes if a.name == name)
        value: str | None = None if text in ("", UNSET) and not spec.required else text
        if value is not None:
            reason = self.schema.check_value(local(element), name, value, parent_tag(element))
            if reason is not None:
                self.error.setText(reason)
                self.refused.emit(reason)
                self._revert(name)
                return False
        elif spec.required:
            self.error.setText(f"{name} is required")
            self._revert(name)
            return False
        self.error.clear()
        self.document.set_attribute(element, name, value)
        return True

    def _commit_text(self, editor: QLineEdit) -> None:
        if self.element is not None:
            self.document.set_text(self.element, editor.text())

    def _revert(self, name: str) -> None:
        editor = self.editors.get(name)
        if editor is None or self.element is None:
            return
        current = self.element.get(name)
        if isinstance(editor, QComboBox):
            editor.setCurrentText(current if current is not None else UNSET)
        else:
            editor.setText(current or "")

    def _changed(self, element: Element) -> None:
        if element is self.element:
            for name, editor in self.editors.items():
                if name == "#text":
                    continue
                value = element.get(name)
                if isinstance(editor, QComboBox):
                    editor.setCurrentText(value if value is not None else UNSET)
                elif editor.text() != (value or ""):
                    editor.setText(value or "")
