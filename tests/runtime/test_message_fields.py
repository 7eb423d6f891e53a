"""``verify`` against the fields each kind writes (issue M point 1, D277): every standard kind, every port type.

For every built-in kind that implements an interface, and each Output port of it: a topic typed
with each of the port's message types passes, a MessageType of the user's own with every field the
kind writes passes, and one lacking fields is refused at the Output's ``topic`` naming them, the
kind and the port (the corpus lines are in tests/data/verify/expected.json).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

import ckmconf
from runtime.registry import Registry
from runtime.verification.interfaces import STANDARD, Port, provided_by, writes_of
from runtime.verification.verify import verify

LOST = "would be lost"


def _ports() -> list[tuple[str, str, Port, tuple[str, ...]]]:
    """(kind, interface, port, the fields the kind writes onto it) of every built-in implementer."""
    registry = Registry(packages=("ckm",))
    found = []
    for kind in registry.kinds("plugin"):
        cls = registry.find("plugin", kind)
        interface = provided_by(cls)
        if interface is None:
            continue
        ports = {p.name: p for p in STANDARD[interface].outputs}
        for name, fields in writes_of(cls).items():  # Outputs of the kind beyond its interface's ports
            ports.setdefault(name, Port(name, "", (), tuple(fields)))
        for port in ports.values():
            written = tuple(writes_of(cls).get(port.name, port.fields))
            if written:
                found.append((kind, interface, port, written))
    return found


PORTS = _ports()


def _types(name: str, written: tuple[str, ...]) -> str:
    """MessageTypes holding exactly the field paths ``written`` (nested ones as their own types)."""
    tree: dict[str, Any] = {}
    for path in written:
        node = tree
        for part in path.split("."):
            node = node.setdefault(part, {})
    out: list[str] = []

    def emit(type_name: str, fields: dict[str, Any]) -> None:
        lines = []
        for field, sub in fields.items():
            field_name = field.removesuffix("[]")
            count = ' count="0"' if field.endswith("[]") else ""
            if sub:
                emit(f"{type_name}_{field_name}", sub)
                lines.append(f'<Field name="{field_name}" type="{type_name}_{field_name}"{count}/>')
            else:
                lines.append(f'<Field name="{field_name}" type="float64"/>')
        out.append(f'<MessageType name="{type_name}">{"".join(lines)}</MessageType>')

    emit(name, tree)
    return "".join(out)


def _system(tmp_path: Path, kind: str, port: str, topic_type: str, types: str = "") -> list[str]:
    """verify's messages for one service of ``kind`` publishing Output ``port`` onto a ``topic_type`` topic
    (with a second Output for a kind of several result ports: one Output alone would carry the whole result)."""
    registry = Registry(packages=("ckm",))
    interface = provided_by(registry.find("plugin", kind))
    several = interface is not None and len(STANDARD[interface].outputs) > 1
    other = '<Output name="other" topic="/other"/>' if several else ""
    path = tmp_path / f"{kind}_{port}.xml"
    path.write_text(f"""<System xmlns="urn:ckm:1" version="1.0" name="fields">{types}
  <Topic name="/out" type="{topic_type}"/><Topic name="/other" type="bytes"/>
  <Node name="robot"/>
  <SmartResource name="R" node="robot">
    <Plugin name="p" kind="{kind}"/>
    <Profile name="P"><Use plugin="p"/></Profile>
    <Service name="S">
      <Output name="{port}" topic="/out"/>{other}
      <QualityMeasure name="latency" kind="qos" domain="temporal" source="latency" unit="s"/>
      <Scenario name="P" profile="P"><Policy measure="latency" upper="0.5"/></Scenario>
    </Service>
  </SmartResource>
</System>""")
    return [e.message for e in verify(ckmconf.load(str(path)), registry)]


def test_every_standard_kind_and_typed_port_is_covered() -> None:
    kinds = {kind for kind, *_ in PORTS}
    assert {"laser-scan", "base-displacement", "amcl-navigation", "orb-recognition", "keypoint-matching",
            "kdtree-shape-classifier", "feature-fusion", "pan-tilt-track", "localization", "arm-poses"} <= kinds


@pytest.mark.parametrize(("kind", "interface", "port", "written"), PORTS, ids=[f"{k}-{p.name}" for k, _, p, _ in PORTS])
def test_each_port_type_holds_what_each_kind_writes(
    tmp_path: Path, kind: str, interface: str, port: Port, written: tuple[str, ...]
) -> None:
    for message in port.messages:
        lost = [m for m in _system(tmp_path, kind, port.name, message) if LOST in m]
        assert lost == [], f"{kind} onto {message}"


@pytest.mark.parametrize(("kind", "interface", "port", "written"), PORTS, ids=[f"{k}-{p.name}" for k, _, p, _ in PORTS])
def test_a_users_own_type_passes_with_every_field_and_is_refused_without_them(
    tmp_path: Path, kind: str, interface: str, port: Port, written: tuple[str, ...]
) -> None:
    assert [m for m in _system(tmp_path, kind, port.name, "Mine", _types("Mine", written)) if LOST in m] == []
    kept, missing = written[:1], written[1:]
    if not missing:
        return
    (problem,) = [m for m in _system(tmp_path, kind, port.name, "Mine", _types("Mine", kept)) if LOST in m]
    assert f"its plugin 'p' ({kind}) writes" in problem
    assert (f"{interface} Output {port.name!r}" in problem) == (port in STANDARD[interface].outputs)
    named = problem.split("would be lost: ")[1].split(";")[0].split(", ")
    top = {m.split(".")[0].removesuffix("[]") for m in missing} - {kept[0].split(".")[0].removesuffix("[]")}
    assert top <= {n.split(".")[0].removesuffix("[]") for n in named}


def test_a_kind_onto_a_ros_type_of_another_port_is_refused_naming_the_port_type(tmp_path: Path) -> None:
    (problem,) = [m for m in _system(tmp_path, "laser-scan", "scan", "nav_msgs/msg/Odometry") if LOST in m]
    assert "of ROS type nav_msgs/msg/Odometry" in problem and "ranges" in problem
    assert problem.endswith("or type the topic sensor_msgs/msg/LaserScan")


def test_bytes_and_undeclared_kinds_are_not_walked(tmp_path: Path) -> None:
    assert [m for m in _system(tmp_path, "laser-scan", "scan", "bytes") if LOST in m] == []
    assert [m for m in _system(tmp_path, "grayscale", "image", "Mine", _types("Mine", ("x",))) if LOST in m] == []
