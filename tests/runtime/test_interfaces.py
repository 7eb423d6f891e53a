"""Service interfaces and the behaviors' declared uses (issue M, points 1 and 3): declarations, verify, docs.

The corpus lines (a missing alias, a wrong interface, a slip of alias, a service of no interface,
an unknown or disagreeing ``interface=``, a service lacking its interface's ports) are in
``tests/data/verify/expected.json``; here: the declarations themselves, the built-in kinds' honesty
(every alias a behavior reads is declared), the lab's bindings, a ROS-kernel service declared by its
attribute, the write-back and ``ckm-plugins interfaces``.
"""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import pytest

import ckmconf
from ckmconf.model import System
from runtime.plugins_cli import interfaces_markdown, main
from runtime.registry import Registry
from runtime.verification.interfaces import STANDARD, Use, Uses, provided_by, uses_of
from runtime.verification.verify import verify
from tests.conftest import REPO

PAGE = REPO / "docs" / "interfaces.md"
_READS = re.compile(r"""self\.service\(\s*"(\w+)"\s*\)|"(\w+)" in self\.context\.services""")


def builtin() -> Registry:
    return Registry(packages=("ckm",))


def _source(cls: type) -> str:
    """The source of a class and of the project's own classes it inherits from."""
    return "".join(inspect.getsource(c) for c in cls.__mro__ if c.__module__.startswith("plugins."))


def test_every_alias_a_builtin_behavior_reads_is_declared() -> None:
    registry = builtin()
    for kind in registry.kinds("behavior"):
        cls = registry.find("behavior", kind)
        assert cls is not None
        read = {a or b for a, b in _READS.findall(_source(cls))}
        declared = uses_of(cls)
        aliases = set(declared.by_alias()) if declared is not None else set()
        assert read <= aliases, f"behavior.{kind} reads services {sorted(read - aliases)} it does not declare"


def test_every_builtin_plugin_provides_a_standard_interface() -> None:
    registry = builtin()
    provided = {}
    for kind in registry.kinds("plugin"):
        cls = registry.find("plugin", kind)
        raw = getattr(cls, "PROVIDES", None)
        if raw is not None:
            assert raw in STANDARD, f"plugin.{kind} provides unknown interface {raw!r}"
            provided[kind] = provided_by(cls)
    assert provided["amcl-navigation"] == "navigation"
    assert provided["base-displacement"] == "base-drive"
    assert provided["arm-poses"] == "arm-motion"
    assert {provided[k] for k in ("keypoint-matching", "kdtree-shape-classifier", "orb-recognition")} == {
        "object-detection"
    }
    # every interface that a built-in behavior uses has a kind implementing it
    used = {u.interface for k in registry.kinds("behavior") for u in uses_of(registry.find("behavior", k)) or ()}
    assert used <= set(provided.values())


def test_declarations_refuse_an_unknown_interface_and_a_repeated_alias() -> None:
    with pytest.raises(TypeError, match="no interface 'teleport'"):
        Use("go", "teleport")
    with pytest.raises(TypeError, match="declared twice"):
        Uses(Use("nav", "navigation"), Use("nav", "base-drive"))
    declared = Uses(Use("nav", "navigation"), Use("base", "base-drive", optional=True))
    assert [u.alias for u in declared] == ["nav", "base"]
    assert declared.by_alias()["base"].optional


def test_an_undeclared_kind_is_not_checked() -> None:
    class Legacy:  # a third-party behavior written before USES
        pass

    assert uses_of(Legacy) is None
    assert provided_by(Legacy) is None
    assert provided_by(None) is None


def test_the_lab_binds_every_service_to_its_declared_interface() -> None:
    system = ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")
    assert verify(system, builtin()) == []
    registry = builtin()
    services = {f"{r.name}.{s.name}": s for r in system.resources for s in r.services}
    checked = 0
    for behavior in system.behaviors:
        declared = uses_of(registry.find("behavior", behavior.kind))
        for uses in behavior.uses:
            use = declared.by_alias().get(uses.alias) if declared is not None else None
            if use is not None:
                checked += 1
                assert uses.service in services
    assert checked >= 20  # NAV, WAIT, APPR, PICK, DOCK, … each bind their declared aliases


def _ros_system(interface: str) -> str:
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="ros-arm">
  <Topic name="/arm/goal" type="bytes"/>
  <Topic name="/arm/status" type="bytes"/>
  <Node name="robot"/>
  <SmartResource name="Arm" node="robot" kernel="ros">
    <Service name="MoveGroup" interface="{interface}">
      <Input name="goal" topic="/arm/goal"/>
      <Output name="status" topic="/arm/status"/>
    </Service>
  </SmartResource>
  <Behavior name="PICK" kind="pick" timeout="30">
    <Param name="sequence" value="gripper:open arm:grasp"/>
    <Uses service="Arm.MoveGroup" as="arm"/>
  </Behavior>
</System>
"""


def _load_text(tmp_path: Path, text: str) -> System:
    path = tmp_path / "system.xml"
    path.write_text(text, encoding="utf-8")
    return ckmconf.load(path)


def test_a_service_with_no_kind_is_of_the_interface_its_attribute_names(tmp_path: Path) -> None:
    """A ROS-kernel service has no plugin kind: ``interface=`` alone makes it usable as ``arm``."""
    messages = [e.message for e in verify(_load_text(tmp_path, _ros_system("arm-motion")), builtin())]
    assert not [m for m in messages if "PICK" in m], messages
    assert any("ROS kernel" in m for m in messages)  # what issue R will lift
    wrong = [e.message for e in verify(_load_text(tmp_path, _ros_system("navigation")), builtin())]
    assert any("uses 'Arm.MoveGroup' as 'arm', which must be an arm-motion service, not a navigation one" in m
               for m in wrong), wrong
    assert any("is a navigation service (docs/interfaces.md) but has no Output 'pose', Parameter 'goal'" in m
               for m in wrong), wrong


def test_the_interface_attribute_survives_write_back(tmp_path: Path) -> None:
    system = _load_text(tmp_path, _ros_system("arm-motion"))
    assert system.resources[0].services[0].interface == "arm-motion"
    written = tmp_path / "again.xml"
    ckmconf.dump(system, written)
    assert 'interface="arm-motion"' in written.read_text(encoding="utf-8")
    assert ckmconf.load(written).resources[0].services[0].interface == "arm-motion"


def test_docs_interfaces_md_is_current() -> None:
    assert PAGE.read_text(encoding="utf-8") == interfaces_markdown(builtin(), "ckm"), (
        "docs/interfaces.md is stale: run "
        ".venv/bin/ckm-plugins interfaces --markdown --package ckm > docs/interfaces.md"
    )
    for name in STANDARD:
        assert f"## `{name}`" in PAGE.read_text(encoding="utf-8")


def test_ckm_plugins_interfaces_and_show(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["interfaces"], builtin()) == 0
    out = capsys.readouterr().out
    assert "navigation: Localization on the system's map" in out
    assert "  kinds: plugin.amcl-navigation" in out
    assert "behavior.wait-goal (as 'nav')" in out
    assert main(["show", "wait-goal", "amcl-navigation"], builtin()) == 0
    shown = capsys.readouterr().out
    assert "  uses as 'nav': navigation service (the goal driven to and its status)" in shown
    assert "  implements interface: navigation" in shown
    assert main(["show", "--json", "set-nav-goal"], builtin()) == 0
    assert '"optional": true' in capsys.readouterr().out
