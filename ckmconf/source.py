"""Safe parsing of one configuration file, and locating its elements and attributes.

The parser never resolves entities, never reads a DTD and never touches the network; a
DOCTYPE is refused outright because a configuration has no use for one and it is the door
to entity-expansion and external-entity attacks. File size is bounded before reading.
"""

from __future__ import annotations

import bisect
import os
import re
from dataclasses import dataclass, field

from lxml import etree

from .errors import ConfigError, Loc

NAMESPACE = "urn:ckm:1"
_NS_PREFIX = "{" + NAMESPACE + "}"
_SKIP_SPANS = re.compile(rb"<!--.*?-->|<!\[CDATA\[.*?\]\]>|<\?.*?\?>", re.S)


@dataclass(frozen=True)
class Limits:
    """Bounds applied to every file read, so hostile input costs bounded time and memory."""

    max_bytes: int = 64 * 1024 * 1024
    max_files: int = 256
    max_elements: int = 5_000_000


def local_name(tag: object) -> str:
    """The element name without its namespace ("Node" for "{urn:ckm:1}Node")."""
    text = str(tag)
    return text.rsplit("}", 1)[-1]


def in_namespace(tag: object) -> bool:
    return isinstance(tag, str) and tag.startswith(_NS_PREFIX)


@dataclass
class SourceFile:
    """A parsed file with what is needed to point at any of its elements and attributes."""

    path: str
    data: bytes
    root: etree._Element
    _line_starts: list[int] = field(default_factory=list)
    _locs: dict[etree._Element, Loc] = field(default_factory=dict)

    def line_col(self, offset: int) -> tuple[int, int]:
        if not self._line_starts:
            self._line_starts = [0] + [m.end() for m in re.finditer(rb"\n", self.data)]
        line = bisect.bisect_right(self._line_starts, offset)
        return line, offset - self._line_starts[line - 1] + 1

    def loc(self, element: etree._Element) -> Loc:
        """Location of an element's start tag; computed for the whole file on first use."""
        if not self._locs:
            self._index()
        found = self._locs.get(element)
        if found is None:  # an element added after parsing: fall back to libxml2's line
            return Loc(self.path, _line(element), 1, element_path(element))
        return found

    def attr_loc(self, element: etree._Element, attribute: str) -> Loc:
        """Location of ``attribute=`` inside the element's start tag (the tag itself if absent)."""
        return self.attr_loc_at(self.loc(element), attribute)

    def attr_loc_at(self, base: Loc, attribute: str) -> Loc:
        """Location of ``attribute=`` in the start tag that begins at ``base``."""
        start = self._offset_of(base)
        end = self.data.find(b">", start)
        pattern = re.compile(rb"\s" + re.escape(attribute.encode()) + rb"\s*=")
        match = pattern.search(self.data, start, end if end >= 0 else len(self.data))
        xpath = f"{base.xpath}/@{attribute}"
        if match is None:
            return Loc(base.file, base.line, base.column, xpath)
        line, col = self.line_col(match.start() + 1)
        return Loc(base.file, line, col, xpath)

    def _offset_of(self, loc: Loc) -> int:
        if not self._line_starts:
            self.line_col(0)
        return self._line_starts[loc.line - 1] + loc.column - 1

    def _index(self) -> None:
        # Start tags appear in the text in document order, so one forward cursor finds each.
        skips = [(m.start(), m.end()) for m in _SKIP_SPANS.finditer(self.data)]
        paths = _all_paths(self.root)
        cursor = 0
        for element in self.root.iter():
            if not isinstance(element.tag, str):
                continue
            name = element.tag.rsplit("}", 1)[-1]
            qname = f"{element.prefix}:{name}" if element.prefix else name
            pattern = re.compile(rb"<" + re.escape(qname.encode()) + rb"[\s/>]")
            offset = _search_outside(pattern, self.data, cursor, skips)
            if offset < 0:
                self._locs[element] = Loc(self.path, _line(element), 1, paths[element])
                continue
            cursor = offset + 1
            line, col = self.line_col(offset)
            self._locs[element] = Loc(self.path, line, col, paths[element])


def _line(element: etree._Element) -> int:
    line = element.sourceline
    return line if isinstance(line, int) and line > 0 else 1


def _all_paths(root: etree._Element) -> dict[etree._Element, str]:
    paths = {root: "/" + _step(root, None)}
    for parent in root.iter():
        if not isinstance(parent.tag, str):
            continue
        kids = [k for k in parent if isinstance(k.tag, str)]
        totals: dict[str, int] = {}
        for kid in kids:
            totals[kid.tag] = totals.get(kid.tag, 0) + 1
        seen: dict[str, int] = {}
        for kid in kids:
            seen[kid.tag] = seen.get(kid.tag, 0) + 1
            index = seen[kid.tag] if totals[kid.tag] > 1 else None
            paths[kid] = paths[parent] + "/" + _step(kid, index)
    return paths


def _search_outside(pattern: re.Pattern[bytes], data: bytes, start: int, skips: list[tuple[int, int]]) -> int:
    while True:
        match = pattern.search(data, start)
        if match is None:
            return -1
        index = bisect.bisect_right(skips, (match.start(), len(data))) - 1
        if index >= 0 and skips[index][0] <= match.start() < skips[index][1]:
            start = skips[index][1]
            continue
        return match.start()


def element_path(element: etree._Element) -> str:
    """A readable path: /System/Node[@name='base']/Sensor[@name='odom'] or .../Transition[3]."""
    steps: list[str] = []
    node: etree._Element | None = element
    while node is not None:
        parent = node.getparent()
        index = None
        if parent is not None:
            same = [sibling for sibling in parent if sibling.tag == node.tag]
            index = same.index(node) + 1 if len(same) > 1 else None
        steps.append(_step(node, index))
        node = parent
    return "/" + "/".join(reversed(steps))


def _step(element: etree._Element, index: int | None) -> str:
    name = local_name(element.tag)
    key = element.get("name")
    if key is not None:
        quote = '"' if "'" in key else "'"
        return f"{name}[@name={quote}{key}{quote}]"
    return name if index is None else f"{name}[{index}]"


def file_error(path: str, message: str) -> ConfigError:
    """A problem with the file as a whole (missing, too large, not XML…)."""
    return ConfigError(path, 1, 1, "/", message)


def read_source(path: str, limits: Limits) -> SourceFile:
    """Read and parse one file safely; any problem is raised as a located ConfigError."""
    try:
        size = os.stat(path).st_size
    except FileNotFoundError:
        raise file_error(path, "file not found") from None
    except OSError as exc:
        raise file_error(path, f"cannot read file: {exc.strerror}") from None
    if not os.path.isfile(path):
        raise file_error(path, "not a regular file")
    if size > limits.max_bytes:
        raise file_error(path, f"file is {size} bytes, more than the limit of {limits.max_bytes} bytes")
    try:
        with open(path, "rb") as handle:
            data = handle.read(limits.max_bytes + 1)
    except OSError as exc:
        raise file_error(path, f"cannot read file: {exc.strerror}") from None
    return parse_bytes(path, data, limits)


def _parser() -> etree.XMLParser:
    return etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        huge_tree=False,
        collect_ids=False,
    )


_NO_DOCTYPE = "DOCTYPE declarations are not allowed (no DTDs, no entities)"


def _find_doctype(data: bytes) -> int:
    """Offset of a DOCTYPE outside comments, checked before libxml2 sees (and acts on) it."""
    skips = [(m.start(), m.end()) for m in _SKIP_SPANS.finditer(data)]
    return _search_outside(re.compile(rb"<!DOCTYPE", re.I), data, 0, skips)


def parse_bytes(path: str, data: bytes, limits: Limits) -> SourceFile:
    """Parse already-read bytes (the editor and the network agent hand text in directly)."""
    if len(data) > limits.max_bytes:
        raise file_error(path, f"file is {len(data)} bytes, more than the limit of {limits.max_bytes} bytes")
    if not data.strip():
        raise file_error(path, "file is empty")
    doctype = _find_doctype(data)
    if doctype >= 0:
        line, col = SourceFile(path, data, etree.Element("x")).line_col(doctype)
        raise ConfigError(path, line, col, "/", _NO_DOCTYPE)
    try:
        root = etree.fromstring(data, _parser())
    except etree.XMLSyntaxError as exc:
        line, column = exc.position if exc.position else (1, 1)
        message = re.sub(r"(,? line \d+(, column \d+)?)+$", "", (exc.msg or "malformed XML").strip())
        raise ConfigError(path, max(line, 1), max(column, 1), "/", f"malformed XML: {message}") from None
    except ValueError as exc:  # e.g. an encoding declaration lxml cannot honour
        raise file_error(path, f"malformed XML: {exc}") from None
    tree = root.getroottree()
    if getattr(tree.docinfo, "doctype", "") or tree.docinfo.internalDTD is not None:
        offset = data.find(b"<!DOCTYPE")
        source = SourceFile(path, data, root)
        line, col = source.line_col(max(offset, 0))
        raise ConfigError(path, line, col, "/", _NO_DOCTYPE)
    for count, _ in enumerate(root.iter(), start=1):
        if count > limits.max_elements:
            raise file_error(path, f"more than {limits.max_elements} elements")
    return SourceFile(path, data, root)
