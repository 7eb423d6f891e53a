"""Map queries with known answers on the use-case lab (configs/usecase/environment.xml, §6.1)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from plugins.environment.geometry import Footprint
from plugins.environment.map_model import BOUNDS, MapModel, parse_stamp
from plugins.environment.perception import ingest_fused, manage

ROBOT = Footprint.round(0.2, height=0.45)


def test_the_lab_map_holds_its_records(lab: MapModel) -> None:
    assert lab.bounds == (0.0, 0.0, 10.0, 7.0)
    assert sorted(lab.avoided) == ["Column1", "Column2", "EquipmentRack", "PartitionWall"]
    assert len(lab) == 10
    workbench = lab.get("workbench")
    assert workbench.dimension == "3D" and len(workbench.parts) == 5
    assert (workbench.zmin, workbench.zmax) == (0.0, 0.30)
    assert lab.get("desk").dimension == "2D" and lab.get("box_orange").dimension == "2.5D"
    assert lab.get("cylinder_red_stripes").texture == "red_stripes"
    assert lab.get("chair").area == "OfficeArea"
    assert lab.get("workbench").stamp == parse_stamp("2018-06-12T09:00:00Z") == 1528794000.0
    # the desk's 1.6 x 0.8 m rectangle centred at its pose
    assert lab.get("desk").shape.bounds == pytest.approx((4.6, 0.2, 6.2, 1.0))


def test_points_and_footprints_in_avoided_areas_and_collisions(lab: MapModel) -> None:
    assert lab.avoided_at(4.5, 3.5) == ["Column1"]
    assert lab.avoided_at(1.0, 1.0) == []
    assert lab.collisions(ROBOT, 4.5, 3.05) == []  # reaches y = 3.25, the column starts at 3.3
    assert lab.collisions(ROBOT, 4.5, 3.15) == ["Column1"]
    assert lab.collisions(ROBOT, 0.1, 3.5) == [BOUNDS]
    assert lab.collisions(ROBOT, 5.4, 0.6) == ["desk"]
    long_robot = Footprint.rectangle(0.6, 0.2)
    assert lab.collisions(long_robot, 4.5, 3.05, yaw=0.0) == []
    assert lab.collisions(long_robot, 4.5, 3.05, yaw=math.pi / 2) == ["Column1"]  # its 0.6 m now along y


def test_object_heights_decide_what_obstructs(lab: MapModel) -> None:
    # Under the workbench top (0.28 m) only the legs obstruct a 0.2 m tall robot.
    low = Footprint.round(0.1, height=0.2)
    assert lab.collisions(low, 8.1, 6.2) == []
    assert lab.collisions(low, 7.35, 5.9) == ["workbench"]  # a leg at (7.35, 5.9)
    assert lab.collisions(Footprint.round(0.1, height=0.45), 8.1, 6.2)[0] == "workbench"


def test_clearance_and_nearest_objects(lab: MapModel) -> None:
    # (2, 3): the drop table's top (x 0.7-1.3, y 1.6-2.2) is the nearest thing.
    assert lab.clearance(2.0, 3.0) == pytest.approx(math.hypot(0.7, 0.8))
    assert lab.clearance(2.0, 3.0, ROBOT) == pytest.approx(math.hypot(0.7, 0.8) - 0.2, abs=2e-3)
    assert lab.clearance(4.5, 3.5) == 0.0
    nearest = lab.nearest(7.6, 6.0, 3)
    assert [o.name for _, o in nearest] == ["workbench", "cylinder_red_stripes", "box_orange"]
    assert [d for d, _ in nearest] == pytest.approx([0.0, 0.065, math.hypot(0.17, 0.27)], abs=2e-3)
    cylinders = lab.nearest(7.6, 6.0, 2, tag="cylinder")
    assert [o.name for _, o in cylinders] == ["cylinder_red_stripes", "cylinder_blue_dots"]


def test_objects_in_a_region_and_on_the_way(lab: MapModel) -> None:
    assert {o.name for o in lab.in_area("WorkbenchArea")} == {
        "workbench", "cylinder_red_stripes", "cylinder_blue_dots", "cylinder_green_checker", "box_cereal",
        "box_orange",
    }
    assert [o.name for o in lab.in_area("OfficeArea")] == ["desk", "chair"]
    assert lab.on_path([(0.5, 3.5), (9.5, 3.5)], Footprint.round(0.2)) == []
    met = lab.on_path([(0.5, 6.1), (9.5, 6.1)], Footprint.round(0.1))
    names = ["cylinder_red_stripes", "cylinder_blue_dots", "workbench", "cylinder_green_checker", "box_cereal"]
    assert [o.name for o in met] == names


def test_semantic_dictionary_answers_what_can_be_done(lab: MapModel) -> None:
    semantics = lab.semantics
    pick = semantics.can(lab.get("box_cereal"), "pick")
    assert pick is not None and pick.condition == "width at most 0.08 m (gripper opening), mass at most 0.2 kg"
    assert semantics.can(lab.get("desk"), "pick") is None
    actions = semantics.actions(lab.in_area("OfficeArea"))
    assert [(a.target, a.action, a.condition) for a in actions] == [("chair", "push", "nobody seated")]
    assert semantics.is_landmark("table") and not semantics.is_landmark("chair")
    assert semantics.localization_class("chair") == "restricted-area"
    assert semantics.is_mobile("person") and semantics.max_speed("person") == 1.5
    assert not semantics.is_mobile("table")
    with pytest.raises(KeyError, match="no semantic tag 'sofa' in the dictionary"):
        semantics.entry("sofa")


def test_observations_follow_time_marks_dynamics_and_areas(lab: MapModel) -> None:
    stamp = lab.get("chair").stamp
    # a static object keeps its pose; its time mark and reliability are refreshed
    assert lab.observe("workbench", 8.3, 6.0, stamp=stamp + 10, reliability=0.7) == "confirmed"
    bench = lab.get("workbench")
    assert (bench.x, bench.y, bench.stamp, bench.reliability) == (8.1, 6.2, stamp + 10, 0.7)
    # a mobile object moves: queries see it at once
    assert lab.observe("chair", 6.5, 1.0, stamp=stamp + 5) == "moved"
    assert lab.collisions(ROBOT, 6.5, 1.0) == ["chair"] and lab.collisions(ROBOT, 5.3, 1.75) == []
    assert tuple(lab.xy[lab.index["chair"]]) == (6.5, 1.0)
    assert lab.observe("chair", 6.0, 1.0, stamp=stamp + 1) == "stale"  # older than its time mark
    assert lab.observe("chair", 1.0, 1.0, stamp=stamp + 9) == "refused"  # a restricted-area object left its room
    assert (lab.get("chair").x, lab.get("chair").stamp) == (6.5, stamp + 5)


def test_recognised_objects_enter_with_their_reliability(lab: MapModel) -> None:
    """The fusion service's output (plugins/processing/fusion.py) in a frame 1 m along x from the map's."""
    fused = {
        "objects": [
            {"name": "cylinder_red_stripes", "shape": "cylinder", "texture": "red_stripes",
             "x": 6.6, "y": 6.1, "z": 0.36, "reliability": 0.93},
            {"name": "cylinder", "shape": "cylinder", "texture": None, "x": 6.97, "y": 6.14, "z": 0.36,
             "reliability": 0.6},
            {"name": "mug", "shape": "mug", "texture": "blue_dots", "x": 3.0, "y": 4.0, "z": 0.0, "reliability": 0.8},
            {"name": "cylinder_blue_dots", "shape": None, "x": None, "y": None, "z": None,
             "origin": [0, 0, 0], "direction": [1, 0, 0], "reliability": 0.5},
        ],
        "reliability": 0.8,
    }
    later = lab.get("cylinder_red_stripes").stamp + 60
    outcomes = ingest_fused(lab, fused, stamp=later, frame=(1.0, 0.0, 0.0, 0.0))
    assert outcomes == [("cylinder_red_stripes", "confirmed"), ("cylinder_blue_dots", "confirmed"), ("mug-10", "added")]
    assert lab.get("cylinder_red_stripes").reliability == 0.93
    assert lab.get("cylinder_blue_dots").reliability == 0.6
    mug = lab.get("mug-10")
    assert (mug.tag, mug.x, mug.y, mug.texture) == ("mug", 4.0, 4.0, "blue_dots")
    assert (mug.reliability, mug.source) == (0.8, "fusion")
    assert [o.name for _, o in lab.nearest(4.0, 4.1, 1)] == ["mug-10"]


def test_manage_compares_every_perception_with_every_managed_element(lab: MapModel) -> None:
    import numpy as np

    stamp = lab.get("chair").stamp + 1
    perceptions = np.array([[5.32, 1.33], [1.02, 1.9], [2.0, 3.5]])
    counts = manage(lab, perceptions, stamp=stamp, tag="thing")
    assert counts == {"confirmed": 1, "moved": 1, "added": 1, "stale": 0, "refused": 0}
    assert (lab.get("chair").x, lab.get("chair").y) == (5.32, 1.33)
    assert "thing-10" in lab and lab.get("thing-10").tag == "thing"


@pytest.mark.parametrize(
    "path",
    ["usecase/environment.xml", "examples/environment_objects.xml", "examples/split/environment.xml",
     "examples/zoom_map.xml"],
)
def test_every_environment_file_builds_a_map(path: str) -> None:
    from plugins.environment.planner import Planner
    from tests.plugins.environment.conftest import environment

    env = environment(path)
    model = MapModel.from_environment(env)
    assert sorted(model.objects) == sorted(o.name for o in env.objects)
    for obj in model.objects.values():
        assert model.outline.buffer(1e-6).contains(obj.shape.centroid)
        assert model.in_region(obj.shape.centroid.buffer(1e-3))  # the index finds every object
    assert Planner(model, Footprint.round(0.2), resolution=0.2).graph.number_of_nodes() > 0


def test_the_example_objects_have_the_geometry_they_declare() -> None:
    from tests.plugins.environment.conftest import environment

    model = MapModel.from_environment(environment("examples/environment_objects.xml"))
    red, blue = model.get("can-red"), model.get("can-blue")
    assert red.parts == blue.parts and red.texture != blue.texture  # same geometry: told apart by texture
    assert red.shape.equals_exact(_moved(blue.shape, -0.2), 1e-9)
    assert model.get("chair-1").dimension == "2D" and len(model.get("chair-1").parts) == 2
    assert model.get("shelf").dimension == "3D" and model.get("shelf").zmax == 1.5
    assert model.semantics.localization_class("chair") == "restricted-area"


def _moved(shape, dx: float):  # type: ignore[no-untyped-def]
    from shapely import affinity

    return affinity.translate(shape, dx, 0.0)


def test_segments_for_a_planar_sensor_follow_its_height(lab: MapModel) -> None:
    low = lab.segments(0.1)  # a laser 0.1 m above the floor
    high = lab.segments(1.0)
    assert low.shape[1] == 4 and len(low) > len(high)
    # the map outline, the four avoided rectangles and the desk (2D: every height) at 2.9 m: 6 × 4 edges
    assert len(lab.segments(2.9)) == 24
    # at 0.1 m the workbench's legs (4 circles) are seen, its top (0.28-0.30 m) is not
    legs = [row for row in low.tolist() if 7.3 <= row[0] <= 8.9 and 5.85 <= row[1] <= 6.55]
    assert legs and all(math.hypot(x - 8.1, y - 6.2) > 0.7 for x, y, _, _ in legs)
    # the chair (mobile) only when asked
    def near_chair(rows: np.ndarray) -> list[list[float]]:
        return [row for row in rows.tolist() if math.hypot(row[0] - 5.3, row[1] - 1.35) < 0.31]

    assert near_chair(lab.segments(0.1, include_mobile=True)) and not near_chair(low)
