"""configs/warehouse (issue N point 3a, D304): the reference system validates with no problem, its
plans are coherent off-line, a mistake in it is refused by ``ckm-validate`` at its line, and its
plan ``pick`` — the carrier's half of the fetch — runs under ckm-run on the lock-step clock with the
parcel stored nearer the carrier (a copy of the configuration, so that CI stays short): the carrier
is sent the parcel's position by the station's signal, drives up to it and clamps and lifts it. The
world's own trace (sim-final.json) is the evidence, not the missions' word."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO
from tests.runtime.network.conftest import private_network

WAREHOUSE = REPO / "configs" / "warehouse"
SYSTEM = WAREHOUSE / "warehouse.xml"


def tool(name: str) -> str:
    return str(Path(sys.executable).parent / name)


def test_the_warehouse_validates_and_its_plans_are_coherent() -> None:
    done = subprocess.run([tool("ckm-validate"), str(SYSTEM)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    checked = subprocess.run([tool("ckm-mission"), "validate", str(SYSTEM)], capture_output=True, text=True,
                             timeout=300)
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert "plan fetch: coherent (3 agents)" in checked.stdout and "plan pick: coherent" in checked.stdout


@pytest.mark.parametrize(
    ("name", "old", "new", "message"),
    [
        ("fetch.xml", '<Param name="object" value="parcel"/>', '<Param name="object" value="parcle"/>', "parcle"),
        ("carrier.xml", '<Param name="particles" value="2500"/>', '<Param name="particles" value="5"/>',
         "particles"),
        ("carrier.xml", 'value="down: 0.0; carry: 0.28; table: 0.21"', 'value="down: 0.0; carry; table: 0.21"',
         "poses"),
        ("carrier.xml", 'value="down: 0.0; carry: 0.28; table: 0.21"',
         'value="down: 0.0; carry: 0.28 0.1; table: 0.21"', "pose 'carry' needs one value per joint"),
        ("carrier.xml", 'value="down: 0.0; carry: 0.28; table: 0.21"', 'value="down: 0.0; carry: 0.45; table: 0.21"',
         "outside its limits 0.0 to 0.3"),
        ("station.xml", '<Param name="poses" value="front: 0.0; back: 3.1416"/>',
         '<Param name="poses" value="front: 0.0; back: 3.1416"/><Param name="contactPoses" value="down"/>',
         "names pose 'down'"),
        ("warehouse.xml", '<Expect object="parcel" on="station_table"', '<Expect object="parcel" on="station_tabel"',
         "station_tabel"),
    ],
)
def test_a_mistake_in_the_warehouse_is_refused_at_its_line(tmp_path: Path, name: str, old: str, new: str,
                                                           message: str) -> None:
    shutil.copytree(WAREHOUSE, tmp_path / "warehouse")
    edited = tmp_path / "warehouse" / name
    text = edited.read_text()
    assert old in text
    line = text[: text.index(old)].count("\n") + 1
    edited.write_text(text.replace(old, new, 1))
    done = subprocess.run([tool("ckm-validate"), str(tmp_path / "warehouse" / "warehouse.xml")], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 1, done.stdout + done.stderr
    assert message in done.stdout and f"{name}:{line}:" in done.stdout, done.stdout


def test_the_carrier_picks_the_parcel_it_was_signalled(tmp_path: Path) -> None:
    """The plan ``pick`` with the parcel stored 2.4 m ahead of the carrier, in its own aisle."""
    copy = tmp_path / "warehouse"
    shutil.copytree(WAREHOUSE, copy)
    parcel = (3.4, 6.1)
    world = (copy / "aisles.xml").read_text()
    assert '<Pose x="6.8" y="3.3"/>' in world
    stored = f'<Pose x="{parcel[0]}" y="{parcel[1]}"/>'
    (copy / "aisles.xml").write_text(world.replace('<Pose x="6.8" y="3.3"/>', stored))
    station = (copy / "station.xml").read_text()
    assert "x: 6.8; y: 3.3" in station
    (copy / "station.xml").write_text(station.replace("x: 6.8; y: 3.3", f"x: {parcel[0]}; y: {parcel[1]}"))
    network = private_network()
    run_dir = tmp_path / "pick"
    done = subprocess.run(
        [tool("ckm-run"), str(copy / "warehouse.xml"), "--plan", "pick", "--lockstep", "0.01", "--duration", "45",
         "--log-dir", str(run_dir), "--ports", str(network.discovery_port), str(network.base_port)],
        cwd=REPO, capture_output=True, text=True, timeout=400,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert "carrier: mission ended: picked" in done.stdout and "station: mission ended: ordered" in done.stdout
    final = json.loads((run_dir / "sim-final.json").read_text())
    x, y, z = final["positions"]["parcel"]
    cx, cy, _ = final["positions"]["carrier"]
    assert z > 0.15 + 0.2, z  # lifted: its centre 0.28 m (the lift's carry height) above where it stood
    assert 0.4 < math.dist((x, y), (cx, cy)) < 0.65  # in the clamp, 0.45-0.60 m ahead of the carrier's centre
