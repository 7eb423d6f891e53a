"""ckm-plugins and the generated reference page docs/plugins.md (issue G, point 2)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from plugins.sim import device_table
from plugins.sim.device_table import DEVICES
from runtime.plugins_cli import main, markdown
from runtime.registry import Registry
from runtime.verification.manifest import params_of
from tests.conftest import REPO

PAGE = REPO / "docs" / "plugins.md"


def builtin() -> Registry:
    return Registry(packages=("ckm",))


def test_docs_plugins_md_is_current() -> None:
    """A kind's docstring or manifest changed: regenerate the page and commit it with the change."""
    current = markdown(builtin(), "ckm")
    assert PAGE.read_text(encoding="utf-8") == current, (
        "docs/plugins.md is stale: run .venv/bin/ckm-plugins markdown --package ckm > docs/plugins.md"
    )


def test_every_builtin_kind_is_documented() -> None:
    registry = builtin()
    assert len(registry.names()) >= 30
    for category, kind in registry.names():
        cls = registry.find(category, kind)
        assert cls is not None and (cls.__doc__ or "").strip(), f"{category}.{kind} has no docstring"
        for name, entry in params_of(cls).specs.items():
            assert entry.doc, f"{category}.{kind}: Param {name!r} has no doc"
        assert f"### `{category}.{kind}`" in PAGE.read_text(encoding="utf-8")


def test_list_names_every_kind(capsys: pytest.CaptureFixture[str]) -> None:
    registry = builtin()
    assert main(["list"], registry) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == [f"{c}.{k}" for c, k in registry.names()]
    assert any(line.startswith("controller.pid ") and "anti-windup" in line for line in lines)


def test_list_long_shows_every_kind_with_its_params(capsys: pytest.CaptureFixture[str]) -> None:
    registry = builtin()
    assert main(["list", "--long"], registry) == 0
    out = capsys.readouterr().out
    for category, kind in registry.names():
        assert f"{category}.{kind}  (" in out
    assert "    sequence (string, required): " in out and "    outputLimit (float, inf, (0, inf)): " in out


def test_show_prints_params_and_ports(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["show", "pid", "hardware.loopback"], builtin()) == 0
    out = capsys.readouterr().out
    assert "controller.pid  (plugins.controllers.pid:PID)" in out
    assert "    tau (float, 0, unit s, [0, inf)): Time constant of the derivative's low-pass filter" in out
    assert "  channel sizes: 1" in out


def test_show_prints_the_kind_s_whole_documentation_and_list_a_clean_summary(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """issue N: the sim device table is reachable from the command line, not only from the source."""
    assert main(["show", "hardware.sim"], builtin()) == 0
    out = capsys.readouterr().out
    assert "  A channel served by a device of a simulated robot.\n" in out  # no "see the module docstring"
    assert "stream in, sensor=lidar: a planar lidar" in out  # the device table (D295), after the module's text
    assert "      values: wx [rad/s], wy [rad/s], wz [rad/s], ax [m/s²], ay [m/s²], az [m/s²]\n" in out
    assert main(["list"], builtin()) == 0
    listing = capsys.readouterr().out
    assert "module docstring" not in listing and "module doc)" not in listing


def test_show_hardware_sim_prints_every_device_of_the_table(capsys: pytest.CaptureFixture[str]) -> None:
    """issue N point 1: every kind x direction x device with its values in order and their units, its
    size, modes and Params, as plugins/sim/device_table.py holds them."""
    assert main(["show", "hardware.sim"], builtin()) == 0
    out = capsys.readouterr().out
    for device in DEVICES:
        block = out.split(f"\n  {device.where}: ", 1)
        assert len(block) == 2, f"{device.where} is not in ckm-plugins show hardware.sim"
        values = block[1].split("\n", 2)[1]
        assert values.startswith("      values: " + ", ".join(f"{name} [{unit}]" for name, unit in device.values))
        assert all(f"{name} (required)" in block[1].split("\n\n", 1)[0] for name in device.required)
    assert "  pwm out, joint: a motor: duty" in out and "size: 1; mode: effort | velocity (none given: effort)" in out
    assert "  bus in, sensor=pose: the true planar pose" in out and "values: x [m], y [m], yaw [rad]" in out
    assert "  stream in, sensor=depth:" in out and "values: depth [mm], per pixel" in out


def test_the_markdown_page_holds_the_device_table() -> None:
    page = markdown(builtin(), "ckm")
    assert device_table.markdown() in page.split("### `hardware.sim`", 1)[1].split("\n### ", 1)[0]


def test_docs_simulation_md_device_table_is_current() -> None:
    """The device table of docs/simulation.md is generated: a row changed, regenerate it with the change."""
    page = (REPO / "docs" / "simulation.md").read_text(encoding="utf-8")
    assert page == device_table.regenerated(page), (
        "docs/simulation.md's device table is stale: run .venv/bin/python -m plugins.sim.device_table "
        "docs/simulation.md"
    )


def test_show_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["show", "--json", "behavior.pick"], builtin()) == 0
    [info] = json.loads(capsys.readouterr().out)
    assert info["name"] == "behavior.pick" and info["package"] == "ckm"
    sequence, min_hold = info["params"]
    assert (sequence["name"], sequence["default"], sequence["type"]) == ("sequence", "required", "string")
    assert (min_hold["name"], min_hold["default"]) == ("minHold", "0")  # D251
    assert info["outputs"] == {"*": "mapping"}


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("pdi", "ckm-plugins: no kind 'pdi' is registered (see ckm-plugins list)"),
        (
            "controller.pdi",
            "ckm-plugins: no controller kind 'pdi' (registered: back-off, constant, diff-drive, diff-drive-odometry,"
            " friction-feedforward, gpc, joint-trajectory, pan-tilt-position, pid, ramp-stop, relay, twist-axes)",
        ),
    ],
)
def test_unknown_kind_is_one_line_and_exit_1(name: str, message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["show", name], builtin()) == 1
    captured = capsys.readouterr()
    assert (captured.out, captured.err) == ("", message + "\n")


def test_console_script_in_a_fresh_process() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "runtime.plugins_cli", "show", "wrap-angle"],
        cwd=REPO,
        timeout=120,
        capture_output=True,
        text=True,
    )
    assert (done.returncode, done.stderr) == (0, "")
    assert done.stdout.startswith("function.wrap-angle  (plugins.functions.processing:WrapAngle)")
