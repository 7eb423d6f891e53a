"""The Smart Plugin Topology: profiles built from the configurations, shared prefixes run once per
frame, atomic profile switches at frame boundaries, configuration errors at their element, and the
image plugins."""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import pytest

from ckmconf.errors import ConfigError
from ckmconf.loader import load
from ckmconf.model import Param, params_dict
from ckmconf.model.resources import Plugin, Profile, SmartResource, Use
from plugins.processing.image import Grayscale, Resize, resize
from runtime.registry import Registry, default_registry
from runtime.resources.spt import (
    Composite,
    Context,
    PluginError,
    ProcessingPlugin,
    Topology,
)
from tests.conftest import CONFIGS

VGA = np.arange(480 * 640 * 3, dtype=np.uint32).reshape(480, 640, 3).astype(np.uint8)


class Passthrough(ProcessingPlugin):
    """Stands for a plugin this repository does not implement yet: accepts any Param, passes its input on."""

    def __init__(self, record: Plugin) -> None:
        self.record = record
        self.name = record.name
        self.params: dict[str, Any] = params_dict(record.params)

    def process(self, data: Any, context: Context) -> Any:
        return data


class Describe(Passthrough):
    """A feature-extractor stand-in: says who it is and the shape of the image it saw."""

    def process(self, data: Any, context: Context) -> Any:
        return (self.name, np.asarray(data).shape)


class Counter(ProcessingPlugin):
    """Stateful: counts the frames it saw (state()/restore() carry the count)."""

    PARAMS: ClassVar[Mapping[str, Any]] = {"start": 0}

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        self.count: int = self.params["start"]
        self.log: list[str] = []

    def setup(self) -> None:
        self.log.append("setup")

    def stop(self) -> None:
        self.log.append("stop")

    def process(self, data: Any, context: Context) -> Any:
        self.count += 1
        return data

    def state(self) -> dict[str, Any]:
        return {"count": self.count}

    def restore(self, state: Mapping[str, Any]) -> None:
        self.count = int(state["count"])


def _registry(resource: SmartResource, real: Mapping[str, type[ProcessingPlugin]]) -> Registry:
    """A registry with the real plugins given and stand-ins for every other kind the resource uses."""
    registry = Registry(load_entry_points=False)
    for kind, cls in real.items():
        registry.register("plugin", kind, cls)
    for record in resource.plugins:
        if record.kind not in real:
            recognizer = any(word in record.kind for word in ("match", "shape", "recognition"))
            stand_in = Describe if recognizer else Passthrough
            registry.register("plugin", record.kind, stand_in)
    return registry


@pytest.fixture(scope="module")
def example() -> SmartResource:
    resource = load(CONFIGS / "examples" / "smart_resource_tcm.xml").resource("RGBD")
    assert resource is not None
    return resource


@pytest.fixture(scope="module")
def camera() -> SmartResource:
    resource = load(CONFIGS / "usecase" / "resources.xml").resource("RGBDCamera")
    assert resource is not None
    return resource


def _example_topology(resource: SmartResource) -> Topology:
    return Topology(resource, _registry(resource, {"resize": Resize}))


def _camera_topology(resource: SmartResource) -> Topology:
    return Topology(resource, _registry(resource, {"image-resize": Resize}))


# ---------------------------------------------------------------------- building


def test_profiles_of_the_example_are_built_with_their_outputs(example: SmartResource) -> None:
    topology = _example_topology(example)
    assert set(topology.profiles) == {"vga", "qvga", "qqvga"}
    assert topology.profiles["vga"].output == ("grab", "undistort", "surf-vga")
    assert topology.profiles["qqvga"].output == ("grab", "undistort", "quarter", "surf-qqvga")
    assert isinstance(topology.plugins["half"], Resize)
    # The shared prefix appears once in the plan of two profiles.
    assert topology.paths(["vga", "qvga"]) == [
        ("grab",),
        ("grab", "undistort"),
        ("grab", "undistort", "surf-vga"),
        ("grab", "undistort", "half"),
        ("grab", "undistort", "half", "surf-qvga"),
    ]


def test_profiles_of_the_use_case_share_the_acquisition(camera: SmartResource) -> None:
    topology = _camera_topology(camera)
    assert list(topology.profiles) == ["VGA", "QVGA", "QQVGA", "DEPTH_VGA", "DEPTH_QVGA", "DEPTH_QQVGA"]
    roots = {topology.profiles[name].tree.plugin.name for name in ("VGA", "QVGA", "QQVGA")}
    assert roots == {"rgb_acquire"}
    assert topology.profiles["QVGA"].output == ("rgb_acquire", "rgb_resize_qvga", "orb_qvga", "match_qvga")
    paths = topology.paths(["VGA", "QVGA", "QQVGA"])
    assert paths.count(("rgb_acquire",)) == 1 and len(paths) == 1 + 3 * 3


def test_the_image_plugins_are_registered_as_entry_points() -> None:
    registry = default_registry()
    assert registry.resolve("plugin", "resize") is Resize
    assert registry.resolve("plugin", "image-resize") is Resize
    assert registry.resolve("plugin", "grayscale") is Grayscale


def test_an_unknown_plugin_kind_is_a_config_error_at_the_plugin(example: SmartResource) -> None:
    registry = Registry(load_entry_points=False)
    registry.register("plugin", "camera-acquisition", Passthrough)
    with pytest.raises(ConfigError) as caught:
        Topology(example, registry)
    error = caught.value
    record = next(p for p in example.plugins if p.kind not in ("camera-acquisition",))
    assert record.loc is not None and (error.file, error.line) == (record.loc.file, record.loc.line)
    assert error.xpath.endswith("Plugin[@name='undistort']/@kind")
    assert "undistort" in error.message and "camera-acquisition" in error.message


def test_a_bad_param_is_a_config_error_at_the_plugin(example: SmartResource) -> None:
    bad = Plugin(name="half", kind="resize", params=(Param(name="scale", value="-0.5"),))
    resource = SmartResource(name="R", node="n", plugins=(bad,), profiles=())
    with pytest.raises(ConfigError, match=r"'scale' = -0\.5 must be greater than 0"):
        Topology(resource, _registry(example, {"resize": Resize}))
    unknown = Plugin(name="half", kind="resize", params=(Param(name="factor", value="2"),))
    with pytest.raises(ConfigError, match="takes no parameter 'factor'"):
        Topology(SmartResource(name="R", node="n", plugins=(unknown,)), _registry(example, {"resize": Resize}))


def test_a_use_of_an_undeclared_plugin_or_a_foreign_output_is_a_config_error() -> None:
    registry = Registry(load_entry_points=False)
    registry.register("plugin", "count", Counter)
    plugins = (Plugin(name="a", kind="count"),)
    missing = Profile(name="p", root=Use(plugin="a", uses=(Use(plugin="b"),)))
    with pytest.raises(ConfigError, match="no plugin 'b'") as caught:
        Topology(SmartResource(name="R", node="n", plugins=plugins, profiles=(missing,)), registry)
    assert caught.value.xpath == "/Use/@plugin"
    foreign = Profile(name="p", output="z", root=Use(plugin="a"))
    with pytest.raises(ConfigError, match="output plugin 'z' is not in profile 'p'"):
        Topology(SmartResource(name="R", node="n", plugins=plugins, profiles=(foreign,)), registry)
    registry.register("plugin", "not-a-plugin", dict)
    odd = (Plugin(name="a", kind="not-a-plugin"),)
    with pytest.raises(ConfigError, match="is not a ProcessingPlugin"):
        Topology(SmartResource(name="R", node="n", plugins=odd), registry)


# ---------------------------------------------------------------------- no duplicate processing


def test_a_shared_prefix_runs_once_per_frame(example: SmartResource) -> None:
    topology = _example_topology(example)
    topology.select("client-1", "vga")
    topology.select("client-2", "qvga")
    frames = [topology.run(VGA) for _ in range(5)]
    calls = {name: s.calls for name, s in topology.stats().items()}
    assert calls == {
        "grab": 5,
        "undistort": 5,
        "surf-vga": 5,
        "half": 5,
        "surf-qvga": 5,
        "quarter": 0,
        "surf-qqvga": 0,
    }
    for frame in frames:
        assert frame.outputs == {
            "client-1": ("surf-vga", (480, 640, 3)),
            "client-2": ("surf-qvga", (240, 320, 3)),
        }
    assert [f.index for f in frames] == [0, 1, 2, 3, 4]
    assert topology.stats()["grab"].total > 0.0


def test_private_replicas_process_again_below_the_shared_root(example: SmartResource) -> None:
    topology = _example_topology(example)
    topology.select("client-1", "vga", share=False)
    topology.select("client-2", "vga", share=False)
    topology.select("client-3", "vga")
    frames = [topology.run(VGA) for _ in range(3)]
    calls = {name: s.calls for name, s in topology.stats().items() if s.calls}
    # The root runs once per frame; each replica and the shared service run the rest on their own.
    assert calls == {"grab": 3, "undistort": 9, "surf-vga": 9}
    for frame in frames:
        assert set(frame.outputs) == {"client-1", "client-2", "client-3"}
        assert len(set(frame.outputs.values())) == 1
    topology.select("client-1", "vga")  # sharing again: one run for client-1 and client-3
    topology.release("client-2")
    topology.reset_stats()
    topology.run(VGA)
    assert {name: s.calls for name, s in topology.stats().items() if s.calls} == {
        "grab": 1,
        "undistort": 1,
        "surf-vga": 1,
    }


def test_replicated_services_on_the_use_case_profiles(camera: SmartResource) -> None:
    """Four clients on three resolutions: the frame is acquired once, each resize runs once."""
    topology = _camera_topology(camera)
    topology.select_all({"c1": "VGA", "c2": "QVGA", "c3": "QQVGA", "c4": "QVGA"})
    for _ in range(3):
        frame = topology.run(VGA)
        assert frame.outputs == {
            "c1": ("match_vga", (480, 640, 3)),
            "c2": ("match_qvga", (240, 320, 3)),
            "c3": ("match_qqvga", (120, 160, 3)),
            "c4": ("match_qvga", (240, 320, 3)),
        }
    stats = topology.stats()
    assert stats["rgb_acquire"].calls == 3
    assert stats["rgb_resize_qvga"].calls == 3  # two clients, one computation
    assert stats["match_qqvga"].calls == 3
    assert stats["depth_acquire"].calls == 0


def test_a_plugin_under_another_upstream_chain_runs_again() -> None:
    """The same instance fed by different parents computes twice: its inputs differ."""
    registry = Registry(load_entry_points=False)
    registry.register("plugin", "count", Counter)
    registry.register("plugin", "resize", Resize)
    plugins = (
        Plugin(name="src", kind="count"),
        Plugin(name="half", kind="resize", params=(Param(name="scale", value="0.5"),)),
        Plugin(name="gray", kind="count"),
    )
    a = Profile(name="a", output="gray", root=Use(plugin="src", uses=(Use(plugin="gray"),)))
    b = Profile(name="b", output="gray", root=Use(plugin="src", uses=(Use(plugin="half", uses=(Use(plugin="gray"),)),)))
    topology = Topology(SmartResource(name="R", node="n", plugins=plugins, profiles=(a, b)), registry)
    topology.select_all({"x": "a", "y": "b"})
    frame = topology.run(VGA)
    assert frame.outputs["x"].shape == (480, 640, 3) and frame.outputs["y"].shape == (240, 320, 3)
    assert {n: s.calls for n, s in topology.stats().items()} == {"src": 1, "half": 1, "gray": 2}


# ---------------------------------------------------------------------- switching


class Switcher(Passthrough):
    """Switches every service to ``target`` while a frame is being processed (a TCM acting mid-frame)."""

    topology: Topology | None = None
    target = "qqvga"

    def process(self, data: Any, context: Context) -> Any:
        assert self.topology is not None
        self.topology.select_all(dict.fromkeys(self.topology.selection(), self.target))
        return data


def test_a_switch_requested_mid_frame_applies_from_the_next_frame(example: SmartResource) -> None:
    topology = Topology(example, _registry(example, {"resize": Resize, "undistort": Switcher}))
    switcher = topology.plugins["undistort"]
    assert isinstance(switcher, Switcher)
    switcher.topology = topology
    topology.select_all({"a": "vga", "b": "qvga"})
    first = topology.run(VGA)
    assert first.profiles == {"a": "vga", "b": "qvga"}
    assert first.outputs == {"a": ("surf-vga", (480, 640, 3)), "b": ("surf-qvga", (240, 320, 3))}
    second = topology.run(VGA)
    assert second.profiles == {"a": "qqvga", "b": "qqvga"}
    assert second.outputs == {"a": ("surf-qqvga", (120, 160, 3)), "b": ("surf-qqvga", (120, 160, 3))}


def test_switching_from_another_thread_keeps_every_frame_whole(camera: SmartResource) -> None:
    """A TCM thread flips both clients between resolutions while frames run: every frame has an
    output for every client, from one selection (both on the same profile), matching its profile."""
    topology = _camera_topology(camera)
    shapes = {"VGA": (480, 640, 3), "QVGA": (240, 320, 3), "QQVGA": (120, 160, 3)}
    small = VGA[:240, :320]  # all three resolutions are whole fractions of it or upscales
    topology.select_all({"a": "VGA", "b": "VGA"})
    done = threading.Event()
    switches = 0

    def tcm() -> None:
        nonlocal switches
        names = list(shapes)
        while not done.is_set():
            profile = names[switches % 3]
            topology.select_all({"a": profile, "b": profile})
            switches += 1
            done.wait(0.0005)

    thread = threading.Thread(target=tcm)
    thread.start()
    try:
        seen: set[str] = set()
        frames, deadline = 0, time.monotonic() + 20.0
        while (frames < 300 or switches < 30 or len(seen) < 3) and time.monotonic() < deadline:
            frames += 1
            frame = topology.run(small)
            assert set(frame.outputs) == {"a", "b"}
            assert frame.profiles["a"] == frame.profiles["b"]
            profile = frame.profiles["a"]
            seen.add(profile)
            for client in ("a", "b"):
                assert frame.outputs[client] == (f"match_{profile.lower()}", shapes[profile])
    finally:
        done.set()
        thread.join(timeout=5)
    assert not thread.is_alive()
    assert switches >= 30 and seen == set(shapes)


def test_release_and_unknown_profiles(example: SmartResource) -> None:
    topology = _example_topology(example)
    with pytest.raises(ValueError, match="no profile 'hd'"):
        topology.select("a", "hd")
    assert topology.run(VGA).outputs == {}
    assert topology.stats()["grab"].calls == 0
    topology.select("a", "vga")
    topology.select("b", "qvga")
    topology.release("b")
    assert set(topology.run(VGA).outputs) == {"a"}
    assert topology.stats()["half"].calls == 0
    assert topology.frames == 2


# ---------------------------------------------------------------------- lifecycle, state, failures


class Failing(Passthrough):
    def process(self, data: Any, context: Context) -> Any:
        if context.frame == 0:
            raise ArithmeticError("boom")
        return data


def _counter_topology() -> Topology:
    registry = Registry(load_entry_points=False)
    registry.register("plugin", "count", Counter)
    registry.register("plugin", "fail", Failing)
    plugins = (
        Plugin(name="a", kind="count"),
        Plugin(name="b", kind="count", params=(Param(name="start", value="10"),)),
        Plugin(name="f", kind="fail"),
    )
    profile = Profile(name="p", output="b", root=Use(plugin="a", uses=(Use(plugin="b"), Use(plugin="f"))))
    return Topology(SmartResource(name="R", node="n", plugins=plugins, profiles=(profile,)), registry)


def test_setup_stop_state_and_restore() -> None:
    topology = _counter_topology()
    topology.setup()
    topology.select("s", "p")
    with pytest.raises(PluginError, match="plugin 'f' failed on frame 0") as caught:
        topology.run(1.0)
    assert isinstance(caught.value.__cause__, ArithmeticError)
    assert topology.run(2.0).outputs == {"s": 2.0}
    assert topology.stats()["f"].errors == 1 and topology.stats()["f"].calls == 2
    assert topology.state() == {"a": {"count": 2}, "b": {"count": 12}}
    other = _counter_topology()
    other.restore(topology.state())
    assert other.state() == topology.state()
    topology.stop()
    a = topology.plugins["a"]
    assert isinstance(a, Counter) and a.log == ["setup", "stop"]
    topology.reset_stats()
    assert topology.stats()["a"].calls == 0


def test_composite_nodes_can_be_built_in_code() -> None:
    plugins = [Counter(Plugin(name=n, kind="count")) for n in ("root", "left", "right")]
    tree = Composite(plugins[0], [Composite(plugins[1]), Composite(plugins[2])])
    assert not tree.is_leaf and tree.children[0].is_leaf
    assert [path for path, _ in tree.walk()] == [("root",), ("root", "left"), ("root", "right")]


# ---------------------------------------------------------------------- image plugins


def _plugin(cls: type[ProcessingPlugin], **params: str) -> ProcessingPlugin:
    record = Plugin(name="p", kind="k", params=tuple(Param(name=k, value=v) for k, v in params.items()))
    return cls(record)


def test_resize_averages_whole_blocks_and_samples_otherwise() -> None:
    image = np.array([[0, 2, 4, 6], [2, 4, 6, 8], [10, 10, 20, 20], [10, 10, 20, 21]], dtype=np.uint8)
    assert resize(image, 2, 2).tolist() == [[2, 6], [10, 20]]  # 20.25 rounds to 20
    assert resize(image, 2, 2).dtype == np.uint8
    # Nearest, at the centres of the target pixels: source rows and columns 0, 2, 3.
    assert resize(image, 3, 3).tolist() == [[0, 4, 6], [10, 20, 20], [10, 20, 21]]
    assert resize(image, 2, 2, area=False).tolist() == [[4, 8], [10, 21]]  # rows and columns 1, 3
    assert resize(image, 4, 4) is image
    context = Context(0, 0.0)
    assert _plugin(Resize, scale="0.25").process(VGA, context).shape == (120, 160, 3)
    assert _plugin(Resize, width="320").process(VGA, context).shape == (240, 320, 3)
    assert _plugin(Resize, width="160", height="120").process(VGA, context).shape == (120, 160, 3)
    half = _plugin(Resize, scale="0.5").process(VGA, context)
    expected = VGA.reshape(240, 2, 320, 2, 3).astype(float).mean(axis=(1, 3))
    assert np.array_equal(half, np.floor(expected + 0.5).astype(np.uint8))
    depth = _plugin(Resize, scale="0.5", interpolation="nearest").process(VGA, context)
    assert np.array_equal(depth, VGA[1::2, 1::2])
    with pytest.raises(ValueError, match="is not 'area' or 'nearest'"):
        _plugin(Resize, interpolation="cubic")
    with pytest.raises(ValueError, match="expects an image"):
        _plugin(Resize, scale="0.5").process(np.zeros(5), context)


def test_grayscale_uses_bt601_weights_in_either_channel_order() -> None:
    pixel = np.array([[[200, 100, 50]]], dtype=np.uint8)
    context = Context(0, 0.0)
    assert _plugin(Grayscale).process(pixel, context).tolist() == [[round(0.299 * 200 + 0.587 * 100 + 0.114 * 50)]]
    assert _plugin(Grayscale, order="bgr").process(pixel, context).tolist() == [
        [round(0.114 * 200 + 0.587 * 100 + 0.299 * 50)]
    ]
    assert _plugin(Grayscale).process(VGA, context).shape == (480, 640)
    flat = np.zeros((2, 2), dtype=np.uint8)
    assert _plugin(Grayscale).process(flat, context) is flat
    with pytest.raises(ValueError, match="is not 'rgb' or 'bgr'"):
        _plugin(Grayscale, order="yuv")
