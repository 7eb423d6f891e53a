"""The report's map (Fig. 7.16) with heights (D294): a flat marking is drawn as a pale dashed outline
under the obstacles, an object of any other height as before."""

from __future__ import annotations

from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from ckmconf.model import Environment, MapBounds
from ckmconf.model.environment import EnvObject, Geometry2D, Pose, Rectangle, Semantic, Texture
from runtime.missions.report_figures import draw_environment, is_marking, map_png


def _square(name: str, x: float, height: float | None) -> EnvObject:
    return EnvObject(
        name=name,
        tag="thing",
        texture="blue",
        pose=Pose(x=x, y=1.0),
        geometry=Geometry2D(height=height, atoms=(Rectangle(width=0.5, depth=0.5),)),
    )


ENV = Environment(
    name="e",
    map=MapBounds(xmin=0.0, ymin=0.0, xmax=4.0, ymax=2.0),
    textures=(Texture(name="blue", color="#0000ff"),),
    semantics=(Semantic(tag="thing"),),
    objects=(_square("pad", 1.0, 0.0), _square("desk", 2.0, None), _square("step", 3.0, 0.3)),
)


def test_a_marking_is_drawn_dashed_and_pale_under_the_obstacles() -> None:
    assert [is_marking(o) for o in ENV.objects] == [True, False, False]
    ax = Figure().subplots()
    draw_environment(ax, ENV)
    squares = {
        round(float(patch.get_xy()[:, 0].min()) + 0.25, 2): patch for patch in ax.patches if isinstance(patch, Polygon)
    }
    pad, desk, step = squares[1.0], squares[2.0], squares[3.0]
    assert pad.get_linestyle() == "--" and pad.get_alpha() == 0.45 and pad.get_zorder() < desk.get_zorder()
    for solid in (desk, step):
        assert solid.get_linestyle() == "solid" and solid.get_alpha() is None
        assert solid.get_facecolor()[:3] == (0.0, 0.0, 1.0)


def test_the_map_figure_renders_with_a_marking() -> None:
    png = map_png(ENV, [("robot", "tab:green", [(0.0, 0.5, 1.0), (1.0, 1.5, 1.0)])], [])
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
