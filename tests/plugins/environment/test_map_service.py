"""``plugin.environment-map``: the map as a configurable Smart Resource service (issue I point 1).

Two robots' map services, each fed its own recognition results and the other's updates, converge
on one object list (newer time mark wins); the Params choose the Environment and the Areas the map
holds; ckm-validate checks the Params; and the same two services run in real Smart Resource
runtimes on a private loopback network."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import ckmconf
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.environment.map_service import EnvironmentMap
from plugins.environment.sharing import encode_object
from runtime.network import TopicQoS, open_transport
from runtime.resources import codec
from runtime.resources.resource import SmartResourceRuntime
from runtime.resources.spt import Context
from runtime.verification.verify import verify
from tests.conftest import CONFIGS
from tests.runtime.network.conftest import private_network

BASE = 1528796700.0
"""The lab's latest time mark (its cylinders and boxes)."""
LAB = CONFIGS / "usecase" / "environment.xml"


def service(**params: object) -> EnvironmentMap:
    """The plugin as a ``<Plugin>`` of a file next to the use case's environment.xml declares it."""
    loc = ckmconf.Loc(str(LAB), 1, 1, "/Plugin")
    record = Plugin(name="map", kind="environment-map", loc=loc,
                    params=tuple(Param(name=k, value=str(v)) for k, v in {"environment": LAB.name, **params}.items()))
    made = EnvironmentMap(record)
    made.setup()
    return made


def seen(stamp: float, *objects: tuple[str, str, float, float]) -> dict[str, Any]:
    """A recognition result (the fusion service's output, map frame)."""
    return {"stamp": stamp, "reliability": 0.8, "objects": [
        {"name": name, "shape": shape, "texture": None, "x": x, "y": y, "z": 0.0, "reliability": 0.8,
         "sources": ["xtion"]} for name, shape, x, y in objects]}


def exchange(a: EnvironmentMap, b: EnvironmentMap, inputs_a: dict[str, Any], inputs_b: dict[str, Any],
             frames: int, start: int = 0) -> None:
    """``frames`` frames of both maps, each taking the other's last update (through the codec)."""
    last: dict[str, Any] = {"a": None, "b": None}
    for k in range(start, start + frames):
        out_a = a.process({**inputs_a, "peer": last["b"]}, Context(k, BASE + 100 + k, "TurtlebotMap"))
        out_b = b.process({**inputs_b, "peer": last["a"]}, Context(k, BASE + 100 + k, "NaoMap"))
        for key, out in (("a", out_a), ("b", out_b)):  # the one Output publishes the whole result
            last[key] = codec.decode(codec.encode(out))


def test_two_robots_maps_converge_on_one_object_list_newer_time_marks_winning() -> None:
    turtlebot, nao = service(robot="turtlebot"), service()  # nao's source name: its resource's
    mine = seen(BASE + 10, ("chair", "chair", 6.0, 1.0), ("cup", "box", 2.0, 3.0))
    theirs = seen(BASE + 20, ("chair", "chair", 4.5, 1.5), ("person", "person", 5.0, 3.0))
    theirs["objects"].append({"name": "cylinder", "x": None, "reliability": 0.5})  # a lone ray: no position
    exchange(turtlebot, nao, {"recognized": mine}, {"recognized": theirs}, 4)
    assert turtlebot.model is not None and nao.model is not None
    assert turtlebot.model.fingerprint() == nao.model.fingerprint()
    names = sorted(o.name for o in turtlebot.objects())  # a new object: its name, its robot's, the map's size
    assert names == sorted(["workbench", "drop_table", "shelf", "desk", "chair", "cylinder_red_stripes",
                            "cylinder_blue_dots", "cylinder_green_checker", "box_cereal", "box_orange",
                            "cup@turtlebot-10", "person@NaoMap-10"])
    for model in (turtlebot.model, nao.model):
        chair = model.get("chair")  # both saw it; the Nao later: its pose wins everywhere
        assert (chair.x, chair.y, chair.stamp, chair.source) == (4.5, 1.5, BASE + 20, "NaoMap")
        cup = model.get("cup@turtlebot-10")
        assert (cup.tag, cup.x, cup.y, cup.source, cup.reliability) == ("box", 2.0, 3.0, "turtlebot", 0.8)
    # the same result handed again (the stream gives every input's newest value) is not a new sighting
    assert turtlebot.process({"recognized": mine, "peer": None}, Context(9, BASE + 200, "TurtlebotMap"))["applied"] == 0
    later = seen(BASE + 40, ("chair", "chair", 5.0, 1.2))
    exchange(turtlebot, nao, {"recognized": later}, {"recognized": theirs}, 3, start=10)
    assert (nao.model.get("chair").x, nao.model.get("chair").stamp) == (5.0, BASE + 40)
    assert turtlebot.model.fingerprint() == nao.model.fingerprint()
    copy = service(robot="turtlebot")  # delegation: a copy goes on from the state
    copy.restore(codec.decode(codec.encode(turtlebot.state())))
    assert copy.model is not None and copy.model.fingerprint() == turtlebot.model.fingerprint()


def test_the_params_choose_the_environment_and_the_areas_the_map_holds(tmp_path: Path) -> None:
    bench = service(areas="WorkbenchArea, NaoArea", robot="nao")
    held = sorted(o.name for o in bench.objects())
    assert held == ["box_cereal", "box_orange", "cylinder_blue_dots", "cylinder_green_checker",
                    "cylinder_red_stripes", "workbench"]
    out = bench.process({"recognized": seen(BASE + 5, ("cup", "box", 2.0, 3.0), ("mug", "cylinder", 7.0, 5.0))},
                        Context(0, BASE + 5, "NaoMap"))
    assert bench.model is not None and sorted(o.name for o in bench.objects()) == sorted([*held, "mug@nao-6"])
    assert sorted(o["name"] for o in out["objects"]) == sorted([*held, "mug@nao-6"])  # the first frame: all
    mug = encode_object(bench.model.get("mug@nao-6"))
    outside = mug | {"name": "sofa", "pose": [2.0, 3.0, 0.0, 0.0]}
    inside = mug | {"name": "plate", "pose": [8.0, 5.0, 0.0, 0.0]}
    broken = {"name": "junk", "pose": [1, 2]}
    peer = {"type": "objects", "map": "turtlebot", "stamp": BASE, "objects": [outside, inside, broken]}
    assert bench.process({"peer": peer}, Context(1, BASE + 6, "NaoMap"))["applied"] == 1
    assert "plate" in bench.model and "sofa" not in bench.model and bench.rejected == 1
    with pytest.raises(ValueError, match=r"parameter 'areas' names 'Kitchen', not Areas of environment .*HomeArea"):
        service(areas="HomeArea Kitchen")
    (tmp_path / "part.xml").write_text('<?xml version="1.0"?><Part xmlns="urn:ckm:1" version="1.0"/>')
    with pytest.raises(ValueError, match=r"has no Environment|cannot use environment file"):
        service(environment=str(tmp_path / "part.xml"))
    with pytest.raises(ValueError, match="cannot use environment file"):
        service(environment=str(tmp_path / "missing.xml"))
    with pytest.raises(ValueError, match="input 'recognized' objects\\[0\\]: x, y, z and reliability"):
        bench.process({"recognized": {"objects": [{"name": "cup", "x": "near", "y": 1.0}]}}, Context(2, BASE, "N"))
    with pytest.raises(ValueError, match="input 'peer' is neither a recognition result nor a map update"):
        bench.process({"peer": {"type": "objects"}}, Context(3, BASE, "N"))


def system_xml(map_params: str = "") -> str:
    """Two robots' map services, each taking its recognition and the other's map."""
    measures = "".join(f'<QualityMeasure name="{m}" kind="qos" domain="performance" source="{m}"/>'
                       for m in ("map_objects", "applied"))
    resources = []
    for robot, peer in (("Turtlebot", "Nao"), ("Nao", "Turtlebot")):
        resources.append(f"""
  <SmartResource name="{robot}Map" node="pc">
    <Plugin name="map" kind="environment-map">
      <Param name="environment" value="{LAB}"/>{map_params}
    </Plugin>
    <Profile name="RUN" output="map"><Use plugin="map"/></Profile>
    <Service name="Map" rate="0.1" performance="map_objects">
      <Input name="recognized" topic="/{robot.lower()}/recog"/>
      <Input name="peer" topic="/{peer.lower()}/map"/>
      <Output name="objects" topic="/{robot.lower()}/map"/>
      {measures}
      <Scenario name="RUN" profile="RUN"><Policy measure="applied" upper="1000"/></Scenario>
    </Service>
  </SmartResource>""")
    topics = "".join(f'<Topic name="/{r}/{t}" type="bytes"/>' for r in ("turtlebot", "nao") for t in ("recog", "map"))
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="map-sharing">
  {topics}
  <Node name="pc" kind="service"/>{"".join(resources)}
</System>
"""


def test_ckm_validate_checks_the_kind_and_its_params(tmp_path: Path) -> None:
    (tmp_path / "good.xml").write_text(system_xml('<Param name="areas" value="HomeArea"/>'))
    assert verify(ckmconf.load(tmp_path / "good.xml")) == []
    (tmp_path / "bad.xml").write_text(system_xml('<Param name="fullEvery" value="0"/><Param name="zoom" value="1"/>'))
    problems = [str(e) for e in verify(ckmconf.load(tmp_path / "bad.xml"))]
    assert any("fullEvery" in p for p in problems) and any("zoom" in p for p in problems), problems


def until(predicate: Callable[[], bool], timeout: float = 20.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            if predicate():
                return True
        except RuntimeError:  # a map changed while read from this thread: look again
            pass
        time.sleep(0.05)
    return predicate()


def test_two_robots_map_services_converge_in_smart_resource_runtimes(tmp_path: Path) -> None:
    (tmp_path / "system.xml").write_text(system_xml())
    system = ckmconf.load(tmp_path / "system.xml")
    network = private_network()
    transports = [open_transport(network, name=n) for n in ("robots", "perception")]
    for transport in transports:
        transport.setup()
        transport.start()
    server, perception = transports
    records = [system.resource(name) for name in ("TurtlebotMap", "NaoMap")]
    runtimes = [SmartResourceRuntime(r, server, announce_period=0.2) for r in records if r is not None]
    recog = {r: perception.publisher(TopicQoS(f"/{r}/recog", "ckm/raw")) for r in ("turtlebot", "nao")}
    try:
        for runtime in runtimes:
            runtime.setup()
            runtime.start()
        maps: list[EnvironmentMap] = [r.streams["map"].topology.plugins["map"] for r in runtimes]  # type: ignore[misc]
        for topic in ("/turtlebot/recog", "/nao/recog"):
            assert perception.wait_for_subscribers(topic, 1, 10)
        results = {"turtlebot": seen(BASE + 10, ("cup", "box", 2.0, 3.0), ("chair", "chair", 6.0, 1.0)),
                   "nao": seen(BASE + 20, ("person", "person", 5.0, 3.0), ("chair", "chair", 4.5, 1.5))}

        def converged() -> bool:
            for robot, publisher in recog.items():  # each robot's recognition keeps publishing
                publisher.publish(codec.encode(results[robot]))
            one, two = (m.model.fingerprint() if m.model is not None else [] for m in maps)
            return bool(one) and one == two and {"cup@TurtlebotMap-10", "person@NaoMap-10"} <= {n for n, *_ in one}

        assert until(converged), [sorted(o.name for o in m.objects()) for m in maps]
        for m in maps:
            assert m.model is not None and (m.model.get("chair").x, m.model.get("chair").source) == (4.5, "NaoMap")
        def measured() -> float | None:  # a frame's measures are observed after its map update: poll them too
            last = {name: v for runtime in runtimes for i in runtime.instances() for name, v in i.measures.last.items()}
            return last.get("map_objects")

        assert until(lambda: measured() == 12), measured()
    finally:
        for runtime in runtimes:
            runtime.stop()
        for transport in reversed(transports):
            transport.stop()
