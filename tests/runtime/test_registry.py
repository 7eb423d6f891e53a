"""The registry (runtime/registry.py): lookups that never instantiate, origins, unknown and broken kinds."""

from __future__ import annotations

from pathlib import Path

import pytest

import ckmconf
from ckmconf.model import System
from plugins.controllers.pid import PID
from runtime.plugins_cli import main as plugins_main
from runtime.registry import Registry, RegistryError
from runtime.verification.verify import verify

SYSTEM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="r">
  <Node name="n">
    <Topic name="x" type="float64" scope="internal"/>
    <Controller name="c" kind="{kind}" period="0.1">
      <Input topic="x" role="measure"/>
      <Output topic="x"/>
    </Controller>
  </Node>
</System>
"""


def system(tmp_path: Path, kind: str) -> System:
    path = tmp_path / "r.xml"
    path.write_text(SYSTEM.format(kind=kind))
    return ckmconf.load(path)


def test_builtin_kinds_come_from_the_ckm_distribution() -> None:
    registry = Registry(packages=("ckm",))
    assert registry.origin("controller", "pid") == "ckm"
    assert registry.target("controller", "pid") == "plugins.controllers.pid:PID"
    assert registry.find("controller", "pid") is PID
    assert registry.find("controller", "nope") is None
    assert Registry(packages=()).names() == []


def test_registering_a_name_twice_is_an_error() -> None:
    registry = Registry(load_entry_points=False)
    registry.register("controller", "pid", PID)
    registry.register("controller", "pid", PID)  # the same class again is harmless
    with pytest.raises(RegistryError, match="registered twice"):
        registry.register("controller", "pid", "plugins.controllers.gpc:GPC")
    with pytest.raises(RegistryError, match=r"CATEGORY\.KIND"):
        registry.register("sensor", "x", PID)


def test_unknown_kind_message_suggests_a_close_name() -> None:
    registry = Registry(packages=("ckm",))
    assert registry.missing("controller", "pdi") == (
        "controller kind 'pdi' does not exist in the registry; did you mean 'pid'?"
    )


def test_a_kind_that_cannot_be_imported_is_a_located_problem(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    registry = Registry(load_entry_points=False)
    registry.register("controller", "ghost", "no_such_module_anywhere:Ghost")
    [problem] = verify(system(tmp_path, "ghost"), registry)
    assert problem.line == 5 and problem.xpath.endswith("/Controller[@name='c']/@kind")
    assert problem.message.startswith(
        "controller 'ghost' (no_such_module_anywhere:Ghost) cannot be imported: "
        "No module named 'no_such_module_anywhere'"
    )
    assert plugins_main(["show", "ghost"], registry) == 1
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.startswith("ckm-plugins: controller 'ghost' (no_such_module_anywhere")
