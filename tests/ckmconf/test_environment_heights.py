"""``height`` on ``<Geometry2D>`` and ``<AvoidedArea>`` (D294): read, defaulted, written back, and the
helpers the consumers share (a marking, the height a 2D object stands, an avoided area's top)."""

from __future__ import annotations

from pathlib import Path

import ckmconf
from ckmconf.model.environment import FOOTPRINT_HEIGHT, Geometry2D
from ckmconf.writer import dumps

DOC = """<?xml version="1.0" encoding="UTF-8"?>
<Part xmlns="urn:ckm:1" version="1.0">
  <Environment name="dock">
    <Map xmin="0" ymin="0" xmax="10" ymax="8" height="5"/>
    <AvoidedArea name="rack" height="2.5">
      <Vertex x="4" y="4"/><Vertex x="5" y="4"/><Vertex x="5" y="5"/>
    </AvoidedArea>
    <AvoidedArea name="wall">
      <Vertex x="7" y="0"/><Vertex x="7.2" y="0"/><Vertex x="7.2" y="8"/>
    </AvoidedArea>
    <Semantic tag="thing"/>
    <Object name="pad" tag="thing"><Pose x="1" y="1"/>
      <Geometry2D height="0"><Circle radius="0.5"/></Geometry2D></Object>
    <Object name="crate" tag="thing"><Pose x="2" y="1"/>
      <Geometry2D height="0.4"><Circle radius="0.2"/></Geometry2D></Object>
    <Object name="desk" tag="thing"><Pose x="3" y="1"/>
      <Geometry2D><Circle radius="0.3"/></Geometry2D></Object>
  </Environment>
</Part>
"""


def test_heights_are_read_defaulted_and_written_back(tmp_path: Path) -> None:
    path = tmp_path / "dock.xml"
    path.write_text(DOC)
    env = ckmconf.load(path).environment
    assert env is not None
    rack, wall = env.avoided
    assert (rack.height, wall.height) == (2.5, None)
    assert (rack.top(env.map.height), wall.top(env.map.height)) == (2.5, 5.0)  # no height: the map's
    geometries = [o.geometry for o in env.objects]
    assert all(isinstance(g, Geometry2D) for g in geometries)
    pad, crate, desk = (g for g in geometries if isinstance(g, Geometry2D))
    assert [g.height for g in (pad, crate, desk)] == [0.0, 0.4, None]
    assert [g.marking for g in (pad, crate, desk)] == [True, False, False]
    assert [g.solid_height for g in (pad, crate, desk)] == [0.0, 0.4, FOOTPRINT_HEIGHT]
    written = dumps(env).decode()
    assert 'height="2.5"' in written and '<Geometry2D height="0">' in written
    assert "<Geometry2D>" in written  # no height given stays none given
    again = tmp_path / "again.xml"
    again.write_text(DOC.replace(DOC[DOC.index("  <Environment") : DOC.index("</Part>")], written.split("?>")[-1]))
    assert ckmconf.load(again).environment == env
