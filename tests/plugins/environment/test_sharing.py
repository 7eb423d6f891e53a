"""The map shared between two robots as a Smart Resource service: they converge on one object list.

Two map instances, each with its own transport, on one private loopback network (CKMultiPeer and Zenoh).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import pytest

from ckmconf.model.environment import Environment
from plugins.environment.map_model import MapModel, small_object
from plugins.environment.sharing import FUNCTION, MapShare, decode_object, encode_object
from runtime.network import Transport
from runtime.resources.client import ServiceDirectory
from tests.runtime.network.conftest import TRANSPORTS, private_network, transports  # noqa: F401 (fixture)

TIMEOUT = 15.0


@pytest.fixture(params=TRANSPORTS)
def network(request: pytest.FixtureRequest, transports: Callable[..., Transport]) -> Callable[[str], Transport]:  # noqa: F811
    """Started transports on one private loopback network of each transport kind; all stopped at the end."""
    settings = private_network(request.param)
    return lambda name: transports(settings, name)


def _until(condition: Callable[[], bool], timeout: float = TIMEOUT) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.05)
    return condition()


def test_two_robots_converge_on_one_object_list(network: Callable[[str], Transport], lab_env: Environment) -> None:
    turtlebot, nao = MapModel.from_environment(lab_env), MapModel.from_environment(lab_env)
    base = turtlebot.get("chair").stamp
    # Each robot sees different things; both see the chair, the Nao later and elsewhere.
    turtlebot.observe("chair", 6.0, 1.0, stamp=base + 10, source="turtlebot")
    nao.observe("chair", 4.5, 1.5, stamp=base + 20, source="nao")
    turtlebot.add(small_object("cup", "box", 2.0, 3.0, stamp=base + 5, source="turtlebot"))
    nao.add(small_object("person-1", "person", 5.0, 3.0, stamp=base + 7, source="nao"))
    nao.observe("workbench", 8.1, 6.2, stamp=base + 30, reliability=0.8, source="nao")
    first, second = MapShare(network("turtlebot"), turtlebot, "turtlebot"), MapShare(network("nao"), nao, "nao")
    with first, second:
        assert _until(lambda: turtlebot.fingerprint() == nao.fingerprint()), "the maps never converged"
        assert first.peers == ["/naoMap/Map/objects"] and second.peers == ["/turtlebotMap/Map/objects"]
        with first.lock:  # a later local update travels too
            turtlebot.observe("chair", 5.0, 1.2, stamp=base + 40, source="turtlebot")
        assert _until(lambda: (nao.get("chair").x, nao.get("chair").stamp) == (5.0, base + 40))
        assert _until(lambda: turtlebot.fingerprint() == nao.fingerprint())
    for model in (turtlebot, nao):
        assert sorted(model.objects) == sorted([*(o.name for o in lab_env.objects), "cup", "person-1"])
        chair = model.get("chair")
        assert (chair.x, chair.y, chair.stamp, chair.source) == (5.0, 1.2, base + 40, "turtlebot")
        assert (model.get("workbench").reliability, model.get("workbench").source) == (0.8, "nao")
        assert [o.name for _, o in model.nearest(5.0, 1.2, 1)] == ["chair"]  # the spatial index follows
    assert first.rejected == second.rejected == 0


def test_the_map_service_is_in_the_directory(network: Callable[[str], Transport], lab: MapModel) -> None:
    share = MapShare(network("robot"), lab, "robot", period=0.05)
    directory = ServiceDirectory(network("observer"))
    try:
        with share:
            entry = directory.wait_for("robotMap", "Map", timeout=TIMEOUT)
    finally:
        directory.close()
    outputs = {"objects": "/robotMap/Map/objects"}
    assert (entry["function"], entry["node"], entry["outputs"]) == (FUNCTION, "robot", outputs)


def test_older_updates_lose_and_bad_ones_are_refused(lab: MapModel) -> None:
    chair = lab.get("chair")
    older = encode_object(chair) | {"pose": [6.0, 1.0, 0.0, 0.0], "stamp": chair.stamp - 1}
    assert lab.replace(decode_object(older)) is False and lab.get("chair").x == 5.3
    tie_low = encode_object(chair) | {"pose": [6.0, 1.0, 0.0, 0.0], "source": "a"}
    assert lab.replace(decode_object(tie_low)) is False  # same stamp, "a" < "map"
    tie_high = encode_object(chair) | {"pose": [6.0, 1.0, 0.0, 0.0], "source": "robot"}
    assert lab.replace(decode_object(tie_high)) is True and lab.get("chair").x == 6.0
    copy = decode_object(encode_object(lab.get("workbench")))
    assert copy.shape.equals(lab.get("workbench").shape) and copy.parts == lab.get("workbench").parts
    cases: list[tuple[dict[str, Any], str]] = [
        ({"pose": [1, 2]}, "pose must be"),
        ({"pose": [1.0, float("nan"), 0.0, 0.0]}, "pose must be a number"),
        ({"parts": [[b"junk", 0, 1]]}, "not WKB"),
        ({"reliability": 2.0}, "reliability must be within"),
        ({"name": ""}, "name must be a string"),
        ({"dimension": "4D"}, "dimension must be one of"),
    ]
    for bad, why in cases:
        with pytest.raises(ValueError, match=why):
            decode_object(encode_object(chair) | bad)
