"""Safe parsing of one configuration file (§3.1.5.2), and locating its elements and attributes.

The parser never resolves entities, never reads a DTD and never touches the network; a
DOCTYPE is refused outright because a configuration has no use for one and it is the door
to entity-expansion and external-entity attacks. File size is bounded before reading.
"""

from __future__ import annotations

import bisect
import os
import re
from collections.abc import Iterator
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
    """True if ``tag`` is an element of the CKM namespace (not a comment or a foreign element)."""
    return isinstance(tag, str) and tag.startswith(_NS_PREFIX)


@dataclass
class SourceFile:
    """A parsed file with what is needed to point at any of its elements and attributes.

    Locations are found lazily, walking the file only as far as the element asked for, so
    pointing at the root of a hostile million-element file costs nothing.
    """

    path: str
    data: bytes
    root: etree._Element
    elements: int = 0
    _line_starts: list[int] = field(default_factory=list)
    _locs: dict[etree._Element, Loc] = field(default_factory=dict)
    _walker: Iterator[etree._Element] | None = None
    _skips: list[tuple[int, int]] = field(default_factory=list)
    _cursor: int = 0
    _seen: dict[etree._Element, dict[str, int]] = field(default_factory=dict)

    def line_col(self, offset: int) -> tuple[int, int]:
        """1-based line and column of byte ``offset`` in the file."""
        if not self._line_starts:
            self._line_starts = [0] + [m.end() for m in re.finditer(rb"\n", self.data)]
        line = bisect.bisect_right(self._line_starts, offset)
        return line, offset - self._line_starts[line - 1] + 1

    def loc(self, element: etree._Element) -> Loc:
        """Location of an element's start tag."""
        found = self._locs.get(element)
        if found is None:
            self._index_until(element)
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

    def value_loc_at(self, base: Loc, attribute: str, offset: int) -> Loc:
        """Location of the character ``offset`` of an attribute's value (plain values; escapes shift it)."""
        at = self.attr_loc_at(base, attribute)
        name_start = self.offset_at(at.line, at.column)
        quote = re.compile(rb"=\s*[\"']").search(self.data, name_start)
        if quote is None or at.column == base.column:
            return at
        target = min(quote.end() + max(offset, 0), len(self.data))
        if b"\n" in self.data[quote.end() : target]:
            return at
        line, col = self.line_col(target)
        return Loc(at.file, line, col, at.xpath)

    def text_loc(self, element: etree._Element) -> Loc:
        """Location of the first non-blank text directly inside an element (the element if none)."""
        base = self.loc(element)
        pieces = [(element, (element.text or "").strip())]
        pieces += [(child, (child.tail or "").strip()) for child in element]
        for anchor, snippet in pieces:
            if not snippet:
                continue
            start = self._offset_of(base if anchor is element else self.loc(anchor))
            found = self.data.find(snippet[:20].encode(), start)
            if found >= 0:
                line, col = self.line_col(found)
                return Loc(base.file, line, col, base.xpath)
            break
        return base

    def _offset_of(self, loc: Loc) -> int:
        return self.offset_at(loc.line, loc.column)

    def offset_at(self, line: int, column: int) -> int:
        """Byte offset of a 1-based line and column (clamped to the file)."""
        if not self._line_starts:
            self.line_col(0)
        if line > len(self._line_starts):
            return len(self.data)
        return self._line_starts[max(line, 1) - 1] + column - 1

    def _index_until(self, target: etree._Element) -> None:
        # Start tags appear in the text in document order, so one forward cursor finds each.
        if self._walker is None:
            self._walker = self.root.iter()
            self._skips = [(m.start(), m.end()) for m in _SKIP_SPANS.finditer(self.data)]
        for element in self._walker:
            if isinstance(element.tag, str):
                self._index_one(element)
            if element is target:
                return

    def _index_one(self, element: etree._Element) -> None:
        parent = element.getparent()
        if parent is None:
            path = "/" + _step(element, None)
        else:
            counts = self._seen.setdefault(parent, {})
            count = counts[element.tag] = counts.get(element.tag, 0) + 1
            later = next(element.itersiblings(element.tag), None) is not None
            path = self._locs[parent].xpath + "/" + _step(element, count if count > 1 or later else None)
        name = element.tag.rsplit("}", 1)[-1]
        qname = f"{element.prefix}:{name}" if element.prefix else name
        pattern = re.compile(rb"<" + re.escape(qname.encode()) + rb"[\s/>]")
        offset = _search_outside(pattern, self.data, self._cursor, self._skips)
        if offset < 0:
            self._locs[element] = Loc(self.path, _line(element), 1, path)
            return
        self._cursor = offset + 1
        line, col = self.line_col(offset)
        self._locs[element] = Loc(self.path, line, col, path)


def _line(element: etree._Element) -> int:
    line = element.sourceline
    return line if isinstance(line, int) and line > 0 else 1


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


_PLAIN_NAME = re.compile(r"/?[A-Za-z_][A-Za-z0-9_\-]*(/[A-Za-z_][A-Za-z0-9_\-]*)*")


def _step(element: etree._Element, index: int | None) -> str:
    name = local_name(element.tag)
    key = element.get("name")
    if key is not None and len(key) <= 256 and _PLAIN_NAME.fullmatch(key):
        return f"{name}[@name='{key}']"
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


def _syntax_message(raw: str, data: bytes, line: int, column: int) -> tuple[str, int, int]:
    """libxml2's parser messages in plain words, on one line, without parser-option advice."""
    text = " ".join(raw.split())
    text = re.sub(r", line \d+, column \d+$", "", text)
    if match := re.match(r"Opening and ending tag mismatch: (\S+) line (\d+) and (\S+)", text):
        # libxml2 points just past the closing tag; point at its '<' instead.
        source = SourceFile("", data, etree.Element("x"))
        start = data.rfind(b"</", 0, max(source.offset_at(line, column), 0))
        if start >= 0:
            line, column = source.line_col(start)
        opened, closing = match.group(1), match.group(3)
        return f"</{closing}> closes <{opened}> opened at line {match.group(2)}", line, column
    if match := re.match(r"Couldn't find end of Start Tag (\S+) line (\d+)", text):
        return f"the start tag <{match.group(1)}> (line {match.group(2)}) is never closed with '>'", line, column
    if match := re.match(r"Premature end of data in tag (\S+) line (\d+)", text):
        return f"the file ends before <{match.group(1)}> (opened at line {match.group(2)}) is closed", line, column
    plain = {
        "xmlParseEntityRef: no name": "a bare '&' must be written &amp;",
        "AttValue: \" or ' expected": "attribute values must be in quotes",
        "Invalid bytes in character encoding": "bytes not valid in the file's encoding (UTF-8 unless declared)",
        "Start tag expected, '<' not found": "not an XML document: no element starts where one should",
        "Extra content at the end of the document": "content after the end of the root element (one root only)",
    }
    for prefix, words in plain.items():
        if text.startswith(prefix):
            return words, line, column
    if text.startswith("Excessive depth in document"):
        return "elements are nested more than 256 levels deep", line, column
    if "Buffer size limit exceeded" in text or "huge input lookup" in text or "XML_PARSE_HUGE" in text:
        return "a text or attribute value is larger than the parser's 10 MB limit", line, column
    return text[:300], line, column


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
        message, line, column = _syntax_message(exc.msg or "", data, line, column)
        raise ConfigError(path, max(line, 1), max(column, 1), "/", f"malformed XML: {message}") from None
    except ValueError as exc:  # e.g. an encoding declaration lxml cannot honour
        raise file_error(path, f"malformed XML: {exc}") from None
    tree = root.getroottree()
    if getattr(tree.docinfo, "doctype", "") or tree.docinfo.internalDTD is not None:
        offset = data.find(b"<!DOCTYPE")
        source = SourceFile(path, data, root)
        line, col = source.line_col(max(offset, 0))
        raise ConfigError(path, line, col, "/", _NO_DOCTYPE)
    count = 0
    for count, _ in enumerate(root.iter(), start=1):
        if count > limits.max_elements:
            raise file_error(path, f"more than {limits.max_elements} elements")
    return SourceFile(path, data, root, elements=count)
