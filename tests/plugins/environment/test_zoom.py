"""The zoom map (§6.1.3, Fig. 6.3; §7.4.1): what configs/examples/zoom_map.xml declares is what it does."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from benchmarks.zoom import scattered_map
from benchmarks.zoom_tour import LAB_GOALS, drive
from ckmconf.model.environment import Environment
from plugins.environment.map_model import MapModel
from plugins.environment.zoom import ZoomMap, ZoomSettings
from tests.plugins.environment.conftest import environment


@pytest.fixture
def corridor() -> Environment:
    return environment("examples/zoom_map.xml")


def test_the_example_declares_what_the_zoom_map_does(corridor: Environment) -> None:
    assert corridor.zoom is not None
    model = MapModel.from_environment(corridor)
    zoom = ZoomMap.of(model, corridor.zoom)
    assert zoom.settings == ZoomSettings("2.5D", 8.0, 6.0, 2.0, 0.1, 10.0, 200)
    assert zoom.update(10.0, 3.0, now=0.0) == "start"
    # 2.5D, 2 m high: the door (2D, projected on the floor) is held, the ceiling lamp (2.6-2.9 m) is not
    assert [o.name for o in zoom.objects] == ["door-1"]
    flat = ZoomMap(model, dataclasses.replace(zoom.settings, mode="2D"))
    flat.update(10.0, 3.0, now=0.0)
    assert [o.name for o in flat.objects] == ["door-1", "lamp-1"]


def test_recentred_within_ten_percent_of_the_border_or_on_time_out(corridor: Environment) -> None:
    assert corridor.zoom is not None
    zoom = ZoomMap.of(MapModel.from_environment(corridor), corridor.zoom)
    zoom.update(10.0, 3.0, now=0.0)
    # 8 m wide: move when closer than 0.8 m to the left/right border, i.e. beyond 3.2 m from the centre
    assert zoom.update(13.15, 3.0, now=1.0) is None
    assert zoom.update(13.25, 3.0, now=2.0) == "border"
    assert (zoom.current.x, zoom.current.y) == (13.25, 3.0)  # type: ignore[union-attr]
    # 6 m deep: beyond 2.4 m from the centre along y
    assert zoom.update(13.25, 0.65, now=3.0) is None
    assert zoom.update(13.25, 0.55, now=4.0) == "border"
    assert zoom.update(13.3, 0.55, now=13.9) is None
    assert zoom.update(13.3, 0.55, now=14.0) == "timeout"
    assert [m.reason for m in zoom.history] == ["start", "border", "border", "timeout"]


def test_the_area_size_follows_the_density_so_the_objects_stay_bounded() -> None:
    dense = scattered_map(20_000, side=60.0, seed=3)  # about 5.6 objects per square metre
    free = ZoomMap(dense, ZoomSettings(width=8.0, depth=6.0))
    free.update(30.0, 30.0, now=0.0)
    assert len(free.rows) > 200  # 48 m² at this density
    bounded = ZoomMap(dense, ZoomSettings(width=8.0, depth=6.0, max_objects=50))
    for step, x in enumerate(np.linspace(5.0, 55.0, 30)):
        bounded.update(float(x), 30.0, now=float(step))
        assert 0 < len(bounded.rows) <= 50
        move = bounded.current
        assert move is not None and move.width / move.depth == pytest.approx(8.0 / 6.0)
    assert bounded.current is not None and bounded.current.width < 8.0
    # the managed objects are exactly the map's objects inside the area
    assert bounded.area is not None
    inside = {o.name for o in dense.in_region(bounded.area)}
    assert {o.name for o in bounded.objects} == inside
    sparse = scattered_map(100, side=60.0, seed=3)
    roomy = ZoomMap(sparse, ZoomSettings(width=8.0, depth=6.0, max_objects=50))
    roomy.update(30.0, 30.0, now=0.0)
    assert (roomy.current.width, roomy.current.depth) == (8.0, 6.0)  # type: ignore[union-attr]


def test_a_cluster_at_the_robot_is_cut_to_the_nearest_objects() -> None:
    model = scattered_map(10, side=20.0, seed=1)
    from plugins.environment.map_model import small_object

    model.add_many([small_object(f"pile{i}", "crate", 10.0, 10.0 + i * 1e-4, radius=0.01) for i in range(30)])
    zoom = ZoomMap(model, ZoomSettings(width=4.0, depth=4.0, max_objects=12))
    zoom.update(10.0, 10.0, now=0.0)
    assert len(zoom.rows) == 12 and {o.name for o in zoom.objects} == {f"pile{i}" for i in range(12)}


def test_perception_updates_touch_only_the_managed_objects() -> None:
    model = scattered_map(2000, side=30.0, seed=5)
    zoom = ZoomMap(model, ZoomSettings(width=6.0, depth=6.0))
    zoom.update(15.0, 15.0, now=0.0)
    managed = [o.name for o in zoom.objects]
    target = model.get(managed[0])
    far = model.nearest(1.0, 1.0, 1)[0][1]
    seen = np.array([[target.x + 0.01, target.y], [far.x, far.y], [15.5, 15.5]])
    before = {o.name: o.stamp for o in model.objects.values()}
    counts = zoom.manage(seen, stamp=50.0, tag="crate")
    assert counts["outside"] == 1  # the far one is out of attention
    assert counts["confirmed"] + counts["moved"] + counts["added"] == 2
    assert model.get(target.name).stamp == 50.0 and model.get(far.name).stamp == before[far.name]
    if counts["added"]:
        assert model.names[int(zoom.rows[-1])] not in before  # a new object inside the area joins it


def test_a_lab_tour_moves_the_area_as_the_robot_nears_its_border(lab_env: Environment) -> None:
    """§7.4.1 / Fig. 7.16 on the use-case lab with its own <ZoomMap> (2.5D, 4 x 4 m, 10 %, 10 s)."""
    assert lab_env.zoom is not None
    model = MapModel.from_environment(lab_env)
    zoom = ZoomMap.of(model, lab_env.zoom)
    tour = drive(model, zoom, LAB_GOALS)
    assert len(tour.legs) == len(LAB_GOALS) - 1
    assert tour.moves[0].reason == "start" and {m.reason for m in tour.moves[1:]} <= {"border", "timeout"}
    assert sum(m.reason == "border" for m in tour.moves) >= 5
    # a border move happens as soon as the robot is nearer than 10 % of the size to the border (0.4 m of 4 m):
    # the step at 0.3 m/s and 10 Hz is 3 cm, so it is past the threshold by at most that
    for before, move in zip(tour.moves, tour.moves[1:], strict=False):
        reach = max(abs(move.x - before.x) / before.width, abs(move.y - before.y) / before.depth)
        if move.reason == "border":
            assert 0.4 < reach <= 0.4 + 0.03 / 4 + 1e-9
            assert move.time - before.time < 10.0
        else:
            assert reach <= 0.4 and 10.0 <= move.time - before.time < 10.0 + 0.1 + 1e-9
