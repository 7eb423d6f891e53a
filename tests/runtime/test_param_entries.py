"""Per-name Param values (``"name: v1 v2; …"``) are declared and checked like any Param (D184):
``ckm-validate`` reports a bad entry at the entry's FILE:LINE:COL, ``read_params`` hands the kind
the parsed value, and both use the one parser."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from ckmconf.model import Param
from runtime.validate_cli import main as validate_main
from runtime.verification.entries import Entries, ParamError
from runtime.verification.manifest import P, Params, read_params
from tests.conftest import REPO

EXAMPLE = REPO / "configs" / "examples" / "service_api.xml"
GOOD = 'value="rgb: line; depth: point"'
PLUGIN = "/System[@name='service-api']/SmartResource[@name='GlobalRecog']/Plugin[@name='fusion']"
OWNER = "processing plugin 'feature-fusion'"


def _position(text: str, needle: str) -> tuple[int, int]:
    before = text[: text.index(needle)]
    return before.count("\n") + 1, len(before.rsplit("\n", 1)[-1]) + 1


def _validate(tmp_path: Path, old: str, new: str, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    path = tmp_path / "service_api.xml"
    shutil.copy(EXAMPLE, path)
    text = path.read_text()
    assert old in text
    text = text.replace(old, new, 1)
    path.write_text(text)
    code = validate_main([str(path)])
    return code, capsys.readouterr().out.strip(), text


def test_the_example_with_per_name_params_validates(capsys: pytest.CaptureFixture[str]) -> None:
    assert validate_main([str(EXAMPLE)]) == 0, capsys.readouterr().out


@pytest.mark.parametrize(
    ("old", "new", "needle", "param", "message"),
    [
        (
            GOOD,
            'value="rgb: line; depth: plane"',
            "depth: plane",
            "inputs",
            "parameter 'inputs' for 'depth' must be 'line' or 'point', got ['plane']",
        ),
        (
            GOOD,
            'value="rgb: line;  rgb line"',
            "rgb line",
            "inputs",
            "parameter 'inputs' entry 'rgb line' is not 'name: values' with a new name",
        ),
        (
            'value="cylinder_red_stripes: cylinder red_stripes;',
            'value="cylinder_red_stripes: a b c;',
            "cylinder_red_stripes: a b c",
            "objects",
            "parameter 'objects' for 'cylinder_red_stripes' needs a shape and maybe a texture",
        ),
        (
            "</Plugin>",
            '<Param name="poses" value="rgb: 0 0 0 0 0 0; lidar: 0 0 0 0 0 0"/></Plugin>',
            "lidar: 0",
            "poses",
            "parameter 'poses' names 'lidar', not an input of 'inputs'",
        ),
        (
            "</Plugin>",
            '<Param name="sigmas" value="depth: 0.02; rgb: x"/></Plugin>',
            "rgb: x",
            "sigmas",
            "parameter 'sigmas' for 'rgb' needs 1 finite number, got ['x']",
        ),
        (
            "</Plugin>",
            '<Param name="cameras" value="rgb: 525 525 319.5 239.5 640 480; depth: 1 1 1 1 1 1"/></Plugin>',
            "depth: 1",
            "cameras",
            "parameter 'cameras' names 'depth', not a line input of 'inputs'",
        ),
    ],
)
def test_ckm_validate_reports_a_bad_entry_at_its_file_line_column(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], old: str, new: str, needle: str, param: str, message: str
) -> None:
    code, out, text = _validate(tmp_path, old, new, capsys)
    line, column = _position(text, needle)
    where = f"{tmp_path / 'service_api.xml'}:{line}:{column}: {PLUGIN}/Param[@name='{param}']/@value"
    assert code == 1
    assert out.splitlines() == [f"{where}: {OWNER}: {message}"]


def test_a_stray_name_in_a_defaulted_reference_is_reported_at_the_param(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # 'inputs' given without 'pantilt': the per-input 'cameras' naming it points at its own entry.
    code, out, text = _validate(
        tmp_path, "</Plugin>", '<Param name="cameras" value="pantilt: 1 1 1 1 1 1"/></Plugin>', capsys
    )
    line, column = _position(text, "pantilt: 1")
    assert code == 1
    assert out.startswith(f"{tmp_path / 'service_api.xml'}:{line}:{column}: ")
    assert out.endswith("parameter 'cameras' names 'pantilt', not a line input of 'inputs'")


SPEC = Params(
    P("inputs", "a: line", "Inputs.", entries=Entries("line|point", choices=("line", "point"))),
    P("poses", "", "Poses.", entries=Entries("x y yaw", 3, numbers=True, of="inputs", noun="an input")),
    P("objects", "", "Objects.", entries=Entries("a shape and maybe a texture", 1, 2)),
    P("sigmas", "", "Sigmas.", entries=Entries("σ", numbers=True, above=0.0)),
)


def _read(**given: str) -> dict[str, object]:
    return read_params([Param(name=k, value=v) for k, v in given.items()], SPEC, owner="k")


def test_the_kind_receives_the_parsed_value_and_a_parsed_default() -> None:
    values = _read(poses=" a: 1 2 3 ;; ", objects="box: box cereal; can: cylinder")
    assert values["inputs"] == {"a": ("line",)}  # the default, parsed like a given value
    assert values["poses"] == {"a": (1.0, 2.0, 3.0)}
    assert values["objects"] == {"box": ("box", "cereal"), "can": ("cylinder",)}
    assert values["sigmas"] == {}


@pytest.mark.parametrize(
    ("given", "message", "offset"),
    [
        ({"poses": "a: 1 2 3; b: 1 2 3"}, "k: parameter 'poses' names 'b', not an input of 'inputs'", 10),
        ({"poses": "a: 1 2 inf"}, "k: parameter 'poses' for 'a' needs 3 finite numbers, got ['1', '2', 'inf']", 0),
        ({"sigmas": "a: 0.1;  b: -1"}, "k: parameter 'sigmas' for 'b' = -1.0 must be greater than 0", 9),
        ({"objects": "x: a b c"}, "k: parameter 'objects' for 'x' needs a shape and maybe a texture", 0),
        (
            {"inputs": "a: line; : point"},
            "k: parameter 'inputs' entry ': point' is not 'name: values' with a new name",
            9,
        ),
    ],
)
def test_a_bad_entry_names_the_param_and_where_it_starts(given: dict[str, str], message: str, offset: int) -> None:
    with pytest.raises(ParamError) as caught:
        _read(**given)
    assert (str(caught.value), caught.value.offset) == (message, offset)


def test_the_reference_shows_the_syntax() -> None:
    assert SPEC.specs["inputs"].range_text() == "'name: line|point; …'"
    assert SPEC.specs["poses"].range_text() == "'name: x y yaw; …'"
