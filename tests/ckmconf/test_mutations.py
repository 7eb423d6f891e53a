"""Property test: whatever is done to a valid file, the loader answers with success or ConfigErrors.

Mutations act on the text (bytes spliced, deleted, duplicated) and on the tree (attributes
changed to odd values, elements removed or repeated), the way a hurried human or a broken
tool would damage a file. Nothing else may come out: no traceback, no hang.
"""

from __future__ import annotations

from pathlib import Path

import xmlschema
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lxml import etree

import ckmconf
from ckmconf import ConfigError, LoadResult
from ckmconf.schema import fast_schema, schema
from tests.conftest import valid_files

SOURCES = [p for p in valid_files() if "split" not in p.parts and "usecase" not in p.parts][:12]
TEXTS = {p: p.read_bytes() for p in SOURCES}
ODD_VALUES = ["", " ", "-1", "0", "1e309", "NaN", "INF", "x" * 300, "a.b", "/t", "'", "<", "&amp;", "\u00e9", "1.5"]


def check(data: bytes, path: Path) -> None:
    try:
        result = ckmconf.load_bytes(data, str(path), strict=False)
    except ConfigError:  # pragma: no cover - lax mode returns errors rather than raising
        raise AssertionError("lax mode raised") from None
    assert isinstance(result, LoadResult)
    assert (result.system is None) == bool(result.errors)
    for error in result.errors:
        assert error.line >= 1 and error.column >= 1 and error.message
    try:
        ckmconf.load_bytes(data, str(path))
    except ConfigError as error:
        assert result.errors and error == result.errors[0]
    validators_agree(data)


def validators_agree(data: bytes) -> None:
    """libxml2 (the fast pass) and xmlschema (the reference) give the same verdict."""
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)
    try:
        tree = etree.fromstring(data, parser).getroottree()
    except (etree.XMLSyntaxError, ValueError):
        return
    if tree.docinfo.internalDTD is not None:
        return
    resource = xmlschema.XMLResource(tree, allow="none", defuse="always")
    assert fast_schema().validate(tree) == schema().is_valid(resource), fast_schema().error_log


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(source=st.sampled_from(SOURCES), data=st.data())
def test_text_mutations(source: Path, data: st.DataObject) -> None:
    text = bytearray(TEXTS[source])
    for _ in range(data.draw(st.integers(1, 3))):
        at = data.draw(st.integers(0, len(text)))
        kind = data.draw(st.sampled_from(["insert", "delete", "duplicate"]))
        if kind == "insert":
            text[at:at] = data.draw(
                st.binary(min_size=1, max_size=8) | st.sampled_from([b"<", b">", b'"', b"&", b"/>"])
            )
        elif kind == "delete":
            del text[at : at + data.draw(st.integers(1, 40))]
        else:
            text[at:at] = text[at : at + data.draw(st.integers(1, 80))]
    check(bytes(text), source)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(source=st.sampled_from(SOURCES), data=st.data())
def test_tree_mutations(source: Path, data: st.DataObject) -> None:
    root = etree.fromstring(TEXTS[source])
    elements = [e for e in root.iter() if isinstance(e.tag, str)]
    for _ in range(data.draw(st.integers(1, 3))):
        target = data.draw(st.sampled_from(elements))
        kind = data.draw(st.sampled_from(["set", "drop-attr", "remove", "repeat"]))
        if kind == "set":
            names = list(target.attrib) or ["name"]
            target.set(data.draw(st.sampled_from(names)), data.draw(st.sampled_from(ODD_VALUES)))
        elif kind == "drop-attr" and target.attrib:
            del target.attrib[data.draw(st.sampled_from(list(target.attrib)))]
        elif kind == "remove" and target.getparent() is not None:
            target.getparent().remove(target)  # type: ignore[union-attr]
            elements = [e for e in root.iter() if isinstance(e.tag, str)]
        elif kind == "repeat" and target.getparent() is not None:
            target.addnext(etree.fromstring(etree.tostring(target)))
    check(etree.tostring(root), source)
