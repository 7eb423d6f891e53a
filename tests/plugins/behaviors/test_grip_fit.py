"""``pick-object``'s Param ``object`` checked by verify against its gripper (D296): an object that fits
the jaw passes, one wider is refused, a name that is no Object of the map is refused; an object's
narrowest width is its shapes' (a rectangle's shorter side, a circle's diameter, a polygon's least
extent); the full opening is the URDF's, for the lab's Turtlebot 0.09 m."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

import ckmconf
from ckmconf.model.environment import (
    Circle,
    EnvObject,
    Geometry2D,
    Geometry25D,
    Polygon,
    Pose,
    Prism,
    Rectangle,
    Vertex,
)
from plugins.behaviors.grip_fit import narrowest
from plugins.sim.urdf import MODELS
from plugins.urdf_model import jaw_opening
from runtime.registry import Registry
from runtime.verification.verify import verify
from tests.conftest import REPO

CORPUS = REPO / "tests" / "data" / "verify" / "sim_pick_object_wider_than_jaw.xml"


def _with_pallet(tmp_path: Path, width: str, depth: str, name: str = "pallet") -> list[str]:
    text = CORPUS.read_text(encoding="utf-8")
    text = text.replace('<Rectangle width="0.6" depth="0.5"/>', f'<Rectangle width="{width}" depth="{depth}"/>')
    text = text.replace('<Param name="object" value="pallet"/>', f'<Param name="object" value="{name}"/>')
    text = text.replace("../../../configs", str(REPO / "configs"))
    path = tmp_path / "cell.xml"
    path.write_text(text, encoding="utf-8")
    return [p.message for p in verify(ckmconf.load(path), Registry(packages=("ckm",)))]


def test_an_object_that_fits_the_jaw_passes_and_a_wider_one_is_refused(tmp_path: Path) -> None:
    assert _with_pallet(tmp_path, "0.6", "0.3") == []  # 0.3 m across its narrower side: the 0.40 m jaw takes it
    [wide] = _with_pallet(tmp_path, "0.6", "0.45")
    assert "0.450 m across at its narrowest, wider than the full opening 0.400 m" in wide


def test_an_object_that_is_no_object_of_the_map_is_refused(tmp_path: Path) -> None:
    [unknown] = _with_pallet(tmp_path, "0.3", "0.3", name="palette")
    assert "parameter 'object' = 'palette' is no Object of the map (its Objects: ['pallet'])" in unknown


def _object(*atoms: Circle | Rectangle | Polygon) -> EnvObject:
    if len(atoms) == 1:
        geometry: Geometry25D | Geometry2D = Geometry25D(prism=Prism(zmax=0.1, base=atoms[0]))
    else:
        geometry = Geometry2D(atoms=atoms)
    return EnvObject(name="o", tag="box", pose=Pose(x=0.0, y=0.0), geometry=geometry)


def test_an_object_s_narrowest_width_is_its_shapes_own() -> None:
    assert narrowest(_object(Rectangle(width=0.6, depth=0.3, yaw=0.7))) == pytest.approx(0.3)
    assert narrowest(_object(Circle(radius=0.035))) == pytest.approx(0.07)
    square = [Vertex(x=math.cos(a), y=math.sin(a)) for a in (0.3, 0.3 + math.pi / 2, 0.3 + math.pi, 0.3 - math.pi / 2)]
    assert narrowest(_object(Polygon(vertices=tuple(square)))) == pytest.approx(math.sqrt(2))  # a turned square
    assert narrowest(_object(Rectangle(width=0.5, depth=0.5), Circle(radius=0.1))) == pytest.approx(0.2)


@pytest.mark.parametrize(
    ("model", "fingers", "opening"),
    [
        ("turtlebot", ("gripper_joint", "gripper_right_joint"), 0.09),
        ("station_arm", ("left_finger_joint", "right_finger_joint"), 0.40),
        ("carrier", ("left_jaw_joint", "right_jaw_joint"), 0.42),
        ("inspection_arm", ("left_finger_joint", "right_finger_joint"), 0.54),
    ],
)
def test_the_full_opening_is_the_urdf_s(model: str, fingers: tuple[str, str], opening: float) -> None:
    assert jaw_opening(MODELS / f"{model}.urdf", fingers) == pytest.approx(opening, abs=1e-6)
    assert jaw_opening(MODELS / f"{model}.urdf", fingers[:1]) is None  # one finger: no jaw to measure
