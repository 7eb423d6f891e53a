"""The editor's schema model: forms, children, order and value checks all come from schemas/.

The editor must be able to edit every file of the repository, refuse invalid values with a
reason at entry, and pick up an element added to the XSD with no change of its own.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from lxml import etree

from editor.model import SchemaModel
from tests.conftest import REPO, valid_files

NS = "{urn:ckm:1}"
SYSTEM_ORDER = [
    "Include",
    "Network",
    "MessageType",
    "Topic",
    "Node",
    "SmartResource",
    "Behavior",
    "CompositionMatrix",
    "Mission",
    "Plan",
    "Validation",
    "Environment",
]


@pytest.fixture(scope="module")
def model() -> SchemaModel:
    return SchemaModel.load()


def _local(tag: str) -> str:
    return tag.removeprefix(NS)


# ---------------------------------------------------------------- every file of the repository


@pytest.mark.parametrize("path", valid_files(), ids=lambda p: str(p.relative_to(REPO / "configs")))
def test_every_element_and_attribute_of_the_configs_has_a_documented_spec(model: SchemaModel, path: Path) -> None:
    root = etree.parse(str(path)).getroot()
    problems: list[str] = []
    for element in root.iter():
        if not isinstance(element.tag, str):
            continue
        ancestors = [_local(a.tag) for a in element.iterancestors()]
        tag = _local(element.tag)
        parent, grandparent = (ancestors[0] if ancestors else None), (ancestors[1] if len(ancestors) > 1 else None)
        spec = model.element(tag, parent, grandparent=grandparent)
        exact = model.element_at([*reversed(ancestors), tag])
        assert (spec.attributes, spec.children, spec.text) == (exact.attributes, exact.children, exact.text)
        if not spec.documentation:
            problems.append(f"{tag}: no documentation")
        names = spec.attribute_names()
        for name, value in ((str(k), str(v)) for k, v in element.attrib.items()):
            if name not in names:
                problems.append(f"{tag}/@{name}: not in the spec")
            elif not spec.attribute(name).documentation:
                problems.append(f"{tag}/@{name}: no documentation")
            elif reason := model.check_value(tag, name, value, parent, grandparent=grandparent):
                problems.append(f"{tag}/@{name}: a valid file is refused: {reason}")
        if spec.has_text and (reason := model.check_text(tag, element.text or "", parent, grandparent=grandparent)):
            problems.append(f"{tag}: a valid text is refused: {reason}")
        children = [_local(c.tag) for c in element if isinstance(c.tag, str)]
        for index, child in enumerate(children):  # each real child would be offered again if removed
            rest = children[:index] + children[index + 1 :]
            if child not in [c.tag for c in model.allowed_children(tag, rest, parent)]:
                problems.append(f"{tag}/{child}: not offered back among {rest}")
    assert not problems, "\n".join(problems)


def test_roots_and_global_versus_local_elements(model: SchemaModel) -> None:
    assert model.roots() == ["System", "Part"]
    assert model.element("System").documentation.startswith("A whole CKM system")
    assert {"Sensor", "Row", "Prism", "Vertex"} <= set(model.tags())


def test_a_tag_that_means_different_things_needs_its_parent(model: SchemaModel) -> None:
    service = model.element("Service", "SmartResource")
    reference = model.element("Service", "CompositionMatrix")
    assert "TCM" in [c.tag for c in service.children] and service.type_name == "ServiceType"
    assert reference.attribute_names() == ["ref"] and reference.children == ()
    with pytest.raises(KeyError, match="'Service' is declared differently under CompositionMatrix, SmartResource"):
        model.element("Service")
    with pytest.raises(KeyError, match="'Service' is not a child of 'Node'"):
        model.element("Service", "Node")
    with pytest.raises(KeyError, match="declares no element 'Nope'"):
        model.element("Nope")
    # Same type under several parents: one spec, the type's documentation when no parent is given.
    assert model.element("Topic").documentation.startswith("A data topic")
    assert model.element("Topic", "Node").documentation.startswith("A topic declared by this node")
    assert model.element_at(["System", "SmartResource", "Service", "Input"]).attribute_names() == ["name", "topic"]
    assert [c.tag for c in model.allowed_children("Service", [], "SmartResource")][-1] == "TCM"
    # Without its grandparent, an ambiguous parent is told apart by the children it holds.
    assert [c.tag for c in model.allowed_children("Service", ["Input"])][-1] == "TCM"
    assert model.child_position("Service", ["Input", "Scenario"], "Output") == 1
    with pytest.raises(KeyError, match="name its parent"):
        model.allowed_children("Service", [])


def test_simple_content_element(model: SchemaModel) -> None:
    row = model.element("Row", "CompositionMatrix")
    assert row.has_text and row.text_kind == "list" and row.text is not None
    assert (row.text.item_kind, row.text.minimum, row.text.maximum) == ("float", 0.0, 1.0)
    assert model.check_text("Row", "0 1 0.5", "CompositionMatrix") is None
    assert model.check_text("Row", "0 2 1", "CompositionMatrix") == "text: 2 is above the maximum 1"
    assert not model.element("Node", "System").has_text


# ---------------------------------------------------------------- types, enumerations, bounds


def test_enumerations_bounds_and_defaults_come_from_the_xsd(model: SchemaModel) -> None:
    reliability = model.element("Topic", "System").attribute("reliability")
    assert (reliability.kind, reliability.enumeration, reliability.default) == (
        "enum",
        ("reliable", "best-effort"),
        "reliable",
    )
    assert not reliability.required
    probability = model.element("Policy", "Scenario").attribute("probability")
    assert (probability.kind, probability.minimum, probability.maximum, probability.default) == (
        "float",
        0.0,
        1.0,
        "0.95",
    )
    assert not probability.min_exclusive and not probability.max_exclusive
    assert probability.type_name == "Fraction" and probability.type_documentation.startswith("A number from 0 to 1")
    period = model.element("Sensor", "Node").attribute("period")
    assert (period.required, period.minimum, period.min_exclusive, period.maximum) == (True, 0.0, True, 86400.0)
    priority = model.element("Controller", "Node").attribute("priority")
    assert (priority.kind, priority.minimum, priority.maximum, priority.default) == ("int", 0.0, 99.0, "50")
    # Controller kinds are registered plugins, so the XSD leaves them open: an identifier, no enumeration.
    kind = model.element("Controller", "Node").attribute("kind")
    assert (kind.kind, kind.enumeration, kind.type_name, kind.max_length) == ("string", (), "Name", 64)
    assert kind.pattern == r"[A-Za-z_][A-Za-z0-9_\-]*"
    assert model.element("Zenoh", "Network").attribute("multicastScouting").kind == "bool"
    assert model.element("Object", "Environment").attribute("stamp").kind == "datetime"
    axes = model.element("Semantic", "Environment").attribute("axes")
    assert (axes.kind, axes.item_kind, axes.enumeration) == ("list", "enum", ("x", "y", "z", "yaw"))
    assert [a.name for a in model.element("Node", "System").attributes] == ["name", "kind", "host", "description"]
    assert "registered controller implementation" in kind.documentation


@pytest.mark.parametrize(
    ("tag", "parent", "attribute", "text", "reason"),
    [
        ("Topic", "System", "reliability", "best-effort", None),
        ("Topic", "System", "reliability", "foo", "reliability: 'foo' is not one of reliable, best-effort"),
        ("Policy", "Scenario", "probability", "0.5", None),
        ("Policy", "Scenario", "probability", "1.5", "probability: 1.5 is above the maximum 1"),
        ("Policy", "Scenario", "probability", "-0.1", "probability: -0.1 is below the minimum 0"),
        ("Policy", "Scenario", "probability", "abc", "probability: 'abc' is not a number"),
        ("Sensor", "Node", "period", "0", "period: 0 must be greater than 0"),
        ("Sensor", "Node", "period", "NaN", "period: 'NaN' is not a number"),
        ("Sensor", "Node", "priority", "1.5", "priority: '1.5' is not a whole number"),
        ("Sensor", "Node", "priority", "100", "priority: 100 is above the maximum 99"),
        ("Node", "System", "name", "", "name: a value is required"),
        (
            "Node",
            "System",
            "name",
            "1abc",
            "name: '1abc' is not a valid Name: an identifier: a letter or underscore, then letters, digits,"
            " '_' or '-' (at most 64 characters)",
        ),
        (
            "Node",
            "System",
            "name",
            "n" * 65,
            "name: 'nnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnn…' is longer than 64 characters",
        ),
        ("Connect", "Zenoh", "endpoint", "tcp/127.0.0.1:7447", None),
        (
            "Connect",
            "Zenoh",
            "endpoint",
            "somewhere",
            r"endpoint: 'somewhere' does not match the pattern (tcp|udp|tls|quic)/[A-Za-z0-9\.\-\[\]:]+:[0-9]{1,5}",
        ),
        ("Zenoh", "Network", "multicastScouting", "yes", "multicastScouting: 'yes' must be true or false"),
        ("Semantic", "Environment", "axes", "x yaw", None),
        ("Semantic", "Environment", "axes", "x w", "axes: 'w' is not one of x, y, z, yaw"),
        ("Polynomial", "Adaptation", "coefficients", "1 2 x", "coefficients: 'x' is not a number"),
        ("Param", "Plugin", "value", "", None),
        ("Node", "System", "bogus", "1", "Node has no attribute 'bogus' (allowed: name, kind, host, description)"),
    ],
)
def test_check_value_accepts_or_refuses_with_the_reason(
    model: SchemaModel, tag: str, parent: str, attribute: str, text: str, reason: str | None
) -> None:
    assert model.check_value(tag, attribute, text, parent) == reason


def test_default_attributes_make_a_new_element_as_valid_as_possible(model: SchemaModel) -> None:
    assert model.default_attributes("System") == {"name": "new_system", "version": "1.0"}
    assert model.default_attributes("Sensor", "Node") == {
        "name": "new_sensor",
        "channel": "channel",
        "topic": "topic",
        "period": "1",
    }
    assert model.default_attributes("HWChannel", "Node") == {"name": "new_hw_channel", "direction": "in"}
    assert model.default_attributes("Connect", "Zenoh") == {"endpoint": "tcp/127.0.0.1:7447"}
    assert model.default_attributes("Circle", "Geometry2D") == {"radius": "1"}
    assert model.default_attributes("Lookup", "Adaptation") == {}
    checked = 0
    for path in _all_paths(model):
        tag = path[-1]
        parent = path[-2] if len(path) > 1 else None
        grandparent = path[-3] if len(path) > 2 else None
        for attribute, value in model.default_attributes(tag, parent, grandparent=grandparent).items():
            assert model.check_value(tag, attribute, value, parent, grandparent=grandparent) is None, (path, attribute)
            checked += 1
    assert checked > 100


def _all_paths(model: SchemaModel) -> list[tuple[str, ...]]:
    """A path from a root to every element of the schema, recursive elements visited once."""
    paths: list[tuple[str, ...]] = []
    todo: list[tuple[str, ...]] = [(root,) for root in model.roots()]
    while todo:
        path = todo.pop()
        paths.append(path)
        todo.extend((*path, c.tag) for c in model.element_at(path).children if c.tag not in path)
    return paths


# ---------------------------------------------------------------- children and their order


def test_allowed_children_respect_max_occurs_and_choices(model: SchemaModel) -> None:
    def offered(parent: str, existing: list[str], grandparent: str | None = None) -> list[str]:
        return [c.tag for c in model.allowed_children(parent, existing, grandparent)]

    assert offered("System", []) == SYSTEM_ORDER
    assert "Network" not in offered("System", ["Network", "Node"])
    assert "TCM" not in offered("Service", ["Scenario", "TCM"], "SmartResource")
    assert "Optional" not in offered("Controller", ["Input", "Output", "Optional"], "Node")
    assert offered("Object", ["Pose", "Geometry2D"], "Environment") == []  # the geometry choice is made
    assert offered("Object", ["Pose"], "Environment") == ["Geometry2D", "Geometry25D", "Geometry3D"]
    assert offered("Prism", ["Circle"], "Geometry3D") == []
    assert offered("Geometry2D", ["Circle"], "Object") == ["Circle", "Rectangle", "Polygon"]
    assert offered("Geometry25D", ["Prism"], "Object") == []
    assert offered("Node", [], "System")[-1] == "Monitor"
    geometry = model.element("Object", "Environment").child("Geometry25D")
    assert (geometry.min_occurs, geometry.max_occurs, geometry.alternatives) == (0, 1, ("Geometry2D", "Geometry3D"))
    assert model.element("Node", "System").child("Sensor").max_occurs is None
    assert model.element("Mission", "System").child("State").min_occurs == 1


def test_child_position_respects_the_system_order(model: SchemaModel) -> None:
    existing = ["Network", "Topic", "Node", "Node", "Mission", "Environment"]
    positions = {tag: model.child_position("System", existing, tag) for tag in SYSTEM_ORDER}
    assert positions == {
        "Include": 0,
        "Network": 1,  # over its maximum: where the order puts it
        "MessageType": 1,
        "Topic": 2,
        "Node": 4,
        "SmartResource": 4,
        "Behavior": 4,
        "CompositionMatrix": 4,
        "Mission": 5,
        "Plan": 5,
        "Validation": 5,
        "Environment": 6,
    }
    for tag, index in positions.items():  # every insertion keeps the declared order
        tags = [*existing[:index], tag, *existing[index:]]
        assert tags == sorted(tags, key=SYSTEM_ORDER.index)


def test_child_position_inside_other_content_models(model: SchemaModel) -> None:
    assert model.child_position("Mission", ["State", "Transition"], "Final", "System") == 1
    assert model.child_position("Mission", ["State", "Final", "Transition"], "State", "System") == 1
    assert model.child_position("Controller", ["Input", "Output", "Switch"], "Optional", "Node") == 2
    # A choice repeated without bound takes its steps in any order: a new step goes last.
    assert model.child_position("Adaptation", ["Linear", "Clamp"], "Median", "Sensor") == 2
    with pytest.raises(KeyError, match="Mission takes no child 'Node'"):
        model.child_position("Mission", [], "Node", "System")


def test_a_large_system_is_answered_quickly(model: SchemaModel) -> None:
    existing = ["Include"] + ["Node"] * 1000 + ["Mission"] * 100
    assert [c.tag for c in model.allowed_children("System", existing)] == SYSTEM_ORDER
    assert model.child_position("System", existing, "Topic") == 1


# ---------------------------------------------------------------- the schema is the only source


def test_an_element_added_to_the_xsd_becomes_editable(tmp_path: Path) -> None:
    shutil.copytree(REPO / "schemas", tmp_path / "schemas")
    kernel = tmp_path / "schemas" / "kernel.xsd"
    text = kernel.read_text(encoding="utf-8")
    anchor = '      <xs:element name="Monitor" type="MonitorType" minOccurs="0">'
    watchdog = """      <xs:element name="Watchdog" minOccurs="0">
        <xs:annotation><xs:documentation>Restarts the node when it stops answering.</xs:documentation></xs:annotation>
        <xs:complexType>
          <xs:attribute name="timeout" type="Seconds" use="required">
            <xs:annotation><xs:documentation>Silence that triggers a restart.</xs:documentation></xs:annotation>
          </xs:attribute>
          <xs:attribute name="mode" default="soft">
            <xs:annotation><xs:documentation>soft or hard restart.</xs:documentation></xs:annotation>
            <xs:simpleType><xs:restriction base="xs:string">
              <xs:enumeration value="soft"/><xs:enumeration value="hard"/>
            </xs:restriction></xs:simpleType>
          </xs:attribute>
        </xs:complexType>
      </xs:element>
"""
    anchor_attribute = '    <xs:attribute name="extrapolation" default="linear">'
    gain = """    <xs:attribute name="gain" type="Fraction" default="1">
      <xs:annotation><xs:documentation>Share of the raw value kept.</xs:documentation></xs:annotation>
    </xs:attribute>
"""
    assert text.count(anchor) == 1 and text.count(anchor_attribute) == 1
    text = text.replace(anchor, watchdog + anchor).replace(anchor_attribute, gain + anchor_attribute)
    kernel.write_text(text, encoding="utf-8")

    model = SchemaModel.load(tmp_path / "schemas")
    assert model is SchemaModel.load(tmp_path / "schemas")  # cached
    assert model is not SchemaModel.load()
    offered = [c.tag for c in model.allowed_children("Node", ["Sensor"], "System")]
    assert offered[-2:] == ["Watchdog", "Monitor"]
    assert model.element("Node", "System").child("Watchdog").documentation == (
        "Restarts the node when it stops answering."
    )
    spec = model.element("Watchdog", "Node")
    assert spec.documentation == "Restarts the node when it stops answering."
    assert [(a.name, a.kind, a.required) for a in spec.attributes] == [
        ("timeout", "float", True),
        ("mode", "enum", False),
    ]
    assert spec.attribute("mode").enumeration == ("soft", "hard")
    assert model.child_position("Node", ["Sensor", "Monitor"], "Watchdog", "System") == 1
    assert model.default_attributes("Watchdog", "Node") == {"timeout": "1"}
    assert model.check_value("Watchdog", "timeout", "-1", "Node") == "timeout: -1 must be greater than 0"
    assert model.check_value("Watchdog", "mode", "medium", "Node") == "mode: 'medium' is not one of soft, hard"
    gain_spec = model.element("Sensor", "Node").attribute("gain")
    assert (gain_spec.documentation, gain_spec.maximum, gain_spec.default) == ("Share of the raw value kept.", 1.0, "1")
    assert model.check_value("Sensor", "gain", "2", "Node") == "gain: 2 is above the maximum 1"
