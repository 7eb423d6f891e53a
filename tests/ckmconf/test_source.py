"""Safe parsing and exact locations."""

from __future__ import annotations

import pytest

from ckmconf.errors import ConfigError
from ckmconf.source import Limits, parse_bytes

DOC = b"""<?xml version="1.0"?>
<System xmlns="urn:ckm:1" version="1.0" name="s">
  <!-- <Node name="in-a-comment"/> -->
  <Node
      name="a"
      host="127.0.0.1"/><Node name="b"/>
</System>
"""


def test_multi_line_start_tags_are_located_at_their_opening_bracket() -> None:
    source = parse_bytes("doc.xml", DOC, Limits())
    a, b = list(source.root)[1:]  # the comment is the first child
    assert (source.loc(a).line, source.loc(a).column) == (4, 3)
    assert (source.loc(b).line, source.loc(b).column) == (6, 25)
    assert source.loc(a).xpath == "/System[@name='s']/Node[@name='a']"


def test_attribute_locations() -> None:
    source = parse_bytes("doc.xml", DOC, Limits())
    a = list(source.root)[1]
    loc = source.attr_loc(a, "host")
    assert (loc.line, loc.column, loc.xpath) == (6, 7, "/System[@name='s']/Node[@name='a']/@host")
    missing = source.attr_loc(a, "kind")
    assert (missing.line, missing.column) == (4, 3)


def test_positional_paths_for_unnamed_siblings() -> None:
    data = b'<Part xmlns="urn:ckm:1" version="1.0"><Include href="a.xml"/><Include href="b.xml"/></Part>'
    source = parse_bytes("p.xml", data, Limits())
    assert [source.loc(e).xpath for e in source.root] == ["/Part/Include[1]", "/Part/Include[2]"]


@pytest.mark.parametrize(
    "data,message",
    [
        (b"", "file is empty"),
        (b"   \n", "file is empty"),
        (b"<System", "malformed XML: the start tag <System> (line 1) is never closed with '>'"),
        (b'<!DOCTYPE x [<!ENTITY a "b">]><x>&a;</x>', "DOCTYPE declarations are not allowed (no DTDs, no entities)"),
        (
            b'<!DOCTYPE x SYSTEM "http://127.0.0.1/x.dtd"><x/>',
            "DOCTYPE declarations are not allowed (no DTDs, no entities)",
        ),
    ],
)
def test_refused_input(data: bytes, message: str) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_bytes("bad.xml", data, Limits())
    assert caught.value.message == message


def test_size_limit_is_checked_before_parsing() -> None:
    with pytest.raises(ConfigError) as caught:
        parse_bytes("big.xml", b"<x/>" + b" " * 100, Limits(max_bytes=50))
    assert caught.value.message == "file is 104 bytes, more than the limit of 50 bytes"


def test_element_count_limit() -> None:
    data = b"<x>" + b"<y/>" * 1000 + b"</x>"
    with pytest.raises(ConfigError) as caught:
        parse_bytes("many.xml", data, Limits(max_elements=500))
    assert caught.value.message == "more than 500 elements"


def test_syntax_error_position() -> None:
    with pytest.raises(ConfigError) as caught:
        parse_bytes("t.xml", b"<a>\n  <b>\n</a>", Limits())
    assert str(caught.value) == "t.xml:3:1: /: malformed XML: </a> closes <b> opened at line 2"
