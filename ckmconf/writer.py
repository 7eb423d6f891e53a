"""Writing records back as XML (the editor's output, §3.1.5.3): stable element and attribute order, two-space indent."""

from __future__ import annotations

import os
from pathlib import Path

from lxml import etree

from .binding import Record, unbind


def dumps(record: Record) -> bytes:
    """The XML text of a record (usually a System or a Part), UTF-8 with a declaration.

    Attributes equal to their schema default are left out, so files stay short and a
    diff shows only what someone chose.
    """
    element = unbind(record)
    etree.indent(element, space="  ")
    return etree.tostring(element, xml_declaration=True, encoding="UTF-8", pretty_print=True)


def dump(record: Record, path: str | os.PathLike[str]) -> None:
    """Write a record to a file atomically (a crash never leaves half a file)."""
    target = Path(path)
    temporary = target.with_name(f".{target.name}.tmp")
    temporary.write_bytes(dumps(record))
    os.replace(temporary, target)
