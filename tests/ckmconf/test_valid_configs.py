"""Every shipped configuration validates with the loader AND with plain xmlschema, and round-trips."""

from __future__ import annotations

from pathlib import Path

import pytest
import xmlschema

import ckmconf
from ckmconf.binding import walk
from ckmconf.model import Part, System
from tests.conftest import REPO, valid_files

FILES = valid_files()
IDS = [str(p.relative_to(REPO)) for p in FILES]


@pytest.fixture(scope="module")
def plain_schema() -> xmlschema.XMLSchema10:
    return xmlschema.XMLSchema10(str(REPO / "schemas" / "ckm.xsd"))


def test_there_are_configs_to_check() -> None:
    assert len(FILES) >= 3
    assert (REPO / "configs" / "usecase" / "lab.xml") in FILES


@pytest.mark.parametrize("path", FILES, ids=IDS)
def test_loader_accepts(path: Path) -> None:
    result = ckmconf.load(path, strict=False)
    assert result.errors == []
    assert isinstance(result.system, System)


@pytest.mark.parametrize("path", FILES, ids=IDS)
def test_plain_xmlschema_accepts(path: Path, plain_schema: xmlschema.XMLSchema10) -> None:
    # The check users asked for: the schemas alone, no project code.
    errors = list(plain_schema.iter_errors(str(path)))
    assert errors == []


@pytest.mark.parametrize("path", FILES, ids=IDS)
def test_document_round_trip(path: Path, tmp_path: Path) -> None:
    document = ckmconf.read_document(path)
    text = ckmconf.dumps(document)
    copy = tmp_path / path.name
    copy.write_bytes(text)
    again = ckmconf.read_document(copy)
    assert again == document
    # Writing is canonical: a second write is byte-identical.
    assert ckmconf.dumps(again) == text


@pytest.mark.parametrize("path", FILES, ids=IDS)
def test_merged_system_round_trip(path: Path) -> None:
    system = ckmconf.load(path)
    text = ckmconf.dumps(system)
    again = ckmconf.load_bytes(text, str(path.with_name("merged.xml")))
    assert again == system
    assert again.includes == ()


@pytest.mark.parametrize("path", FILES, ids=IDS)
def test_every_record_knows_where_it_came_from(path: Path) -> None:
    system = ckmconf.load(path)
    for record in walk(system):
        assert record.loc is not None
        assert record.loc.line >= 1 and record.loc.column >= 1
        assert record.loc.xpath.startswith(("/System", "/Part"))


def test_use_case_is_complete() -> None:
    lab = ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")
    services = {f"{r.name}.{s.name}" for r in lab.resources for s in r.services}
    # Tables 7.1 and 7.2.
    for expected in [
        "RoboticArm.MoveIt",
        "LaserSensor.Scan",
        "RGBDCamera.RGBRecog",
        "RGBDCamera.DepthRecog",
        "MobileBase.Displacement",
        "Navigation.AMCL",
        "GlobalRecog.Fusion",
        "Nao.NaoQi",
        "PanTiltCamera.Track",
        "PanTiltCamera.Recog",
    ]:
        assert expected in services
    behaviors = {b.name for b in lab.behaviors}
    assert {"INIT", "NAV", "WAIT", "SPOT", "APPR", "PICK", "PLACE", "BACK", "END", "OBJ_TRACK", "OBJ_FIX"} <= behaviors
    table_7_6 = next(m for m in lab.matrices if len(m.services) == 7)
    assert table_7_6.rows[6].values == (0, 0, 0.5, 0.5, 0, 0, 1)
    assert table_7_6.rule == "normalize"
    assert any(len(plan.agents) == 2 and plan.dependencies for plan in lab.plans)
    assert lab.environment is not None and len(lab.environment.objects) >= 4


def test_parts_are_parts() -> None:
    for path in FILES:
        document = ckmconf.read_document(path)
        assert isinstance(document, (System, Part))
