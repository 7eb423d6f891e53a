"""The Smart Plugin Topology (SPT, thesis §3.2.2, Fig. 3.11): processing plugins composed at run time.

A Smart Resource declares plugin instances (``<Plugin name kind>``) and execution profiles
(``<Profile>``), each a tree of ``<Use>``: a child consumes its parent's output (the Composite
pattern: a ``Composite`` node is a plugin plus the nodes fed by it, a node without children is a
leaf). Each service runs one ACTIVE profile and delivers the result of that profile's output plugin.

Avoiding process duplicities. Every node is identified by its *path*, the names of the plugins from
the root down to it. Plugin names are unique in a resource, so two nodes with the same path are the
same plugin instance fed by the same upstream chain: for one frame they compute the same value. A
frame therefore runs the active profiles against one memo keyed by path, and a node found in the
memo is not run again. Two services on VGA and QVGA that both start with ``grab → undistort``
grab and undistort once per frame; a plugin shared under different upstream chains runs once per
chain (its input differs). Plugins must treat their input as read-only, since it may be shared.

Switching atomically. ``select()`` (any thread, e.g. the TCM) only updates the requested
selection under a lock; ``run()`` copies the whole selection under that lock when a frame starts
and uses the copy to its end. A switch thus takes effect at the next frame boundary, every frame
runs one consistent selection (all services old or all new, never half-switched), and every
profile is built and set up beforehand, so the switching frame already has its output.

Plugins register under ``plugin.KIND`` in the ``ckm.plugins`` entry points; this module provides
``plugin.resize`` (also ``plugin.image-resize``, the use case's name) and ``plugin.grayscale``.
"""

from __future__ import annotations

import abc
import dataclasses
import os
import pathlib
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

from ckmconf.binding import Record
from ckmconf.errors import ConfigError
from ckmconf.model.resources import Plugin, Profile, SmartResource, Use
from runtime.registry import Registry, default_registry
from runtime.verification.manifest import read_params  # below the kernel: resources never import it

Path = tuple[str, ...]
"""A node's identity: plugin names from the root of its tree down to it."""


@dataclass(frozen=True)
class Context:
    """What a plugin knows about the frame it processes; the same for every service sharing the node."""

    frame: int
    stamp: float
    resource: str = ""


def config_dir(record: Record) -> pathlib.Path:
    """The directory of the configuration file ``record`` was read from, absolute: the files a
    plugin's Params name (a model, an environment, a poses file) are relative to it. A record built
    in code has no file: the working directory."""
    return pathlib.Path(os.path.abspath(record.loc.file)).parent if record.loc is not None else pathlib.Path.cwd()


class ProcessingPlugin(abc.ABC):
    """The SPT plugin interface, built from its ``<Plugin>`` record with no I/O in ``__init__``.

    ``PARAMS`` maps each accepted Param to its default (``read_params``); bad ones raise ParamError,
    which the topology reports as a ConfigError at the Plugin element. Devices open in ``setup()``
    and close in ``stop()``. ``state()``/``restore()`` carry internal state to another node, as for
    controllers, so a processing chain can be delegated.
    """

    PARAMS: ClassVar[Mapping[str, Any]] = {}

    def __init__(self, record: Plugin) -> None:
        self.record = record
        self.name = record.name
        self.params: dict[str, Any] = read_params(record.params, self.PARAMS, owner=self.owner)

    @property
    def owner(self) -> str:
        """How messages name this plugin."""
        return f"plugin {self.record.name!r} ({self.record.kind})"

    def setup(self) -> None:
        """Open devices or load models (no I/O before this)."""
        return None  # optional hook

    @abc.abstractmethod
    def process(self, data: Any, context: Context) -> Any:
        """The result for ``data`` (the parent's result, or the frame for a root); must not modify ``data``.

        A plugin returns None when it has nothing for this frame (a service of several inputs whose
        needed one has not arrived yet, a frame it already processed): the plugins below it do not run
        and the services whose outputs lie in its subtree publish nothing."""

    def stop(self) -> None:
        """Release what ``setup()`` opened."""
        return None  # optional hook

    def state(self) -> dict[str, Any]:
        """The plugin's internal state, msgpack-able (for delegation to another node)."""
        return {}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a state produced by ``state()`` on another node."""
        return None  # optional hook


class PluginError(RuntimeError):
    """A plugin raised while processing a frame (the original exception is the cause)."""

    def __init__(self, plugin: str, frame: int) -> None:
        super().__init__(f"plugin {plugin!r} failed on frame {frame}")
        self.plugin = plugin
        self.frame = frame


@dataclass
class PluginStats:
    """Calls and execution time of one plugin instance (seconds, perf_counter)."""

    calls: int = 0
    errors: int = 0
    total: float = 0.0
    last: float = 0.0
    max: float = 0.0

    @property
    def mean(self) -> float:
        """Mean execution time per call in seconds (0 before the first call)."""
        return self.total / self.calls if self.calls else 0.0


@dataclass
class FramePass:
    """One frame in progress: its context, the memo of node results by path, and the timing sink."""

    context: Context
    memo: dict[Path, Any] = field(default_factory=dict)
    record: Callable[[str, float, bool], None] | None = None


class Composite:
    """A ``<Use>`` of a composition tree (Composite pattern, Fig. 3.11): a plugin and the nodes consuming its output."""

    def __init__(self, plugin: ProcessingPlugin, children: Sequence[Composite] = ()) -> None:
        self.plugin = plugin
        self.children = tuple(children)

    @property
    def is_leaf(self) -> bool:
        """True if no plugin consumes this node's output."""
        return not self.children

    def walk(self, prefix: Path = ()) -> Iterator[tuple[Path, Composite]]:
        """Every node of the subtree with its path, parents first (execution order)."""
        path = (*prefix, self.plugin.name)
        yield path, self
        for child in self.children:
            yield from child.walk(path)

    def run(self, data: Any, frame: FramePass, prefix: Path = ()) -> None:
        """Run the subtree on ``data``; nodes whose path is already in ``frame.memo`` are not run again."""
        path = (*prefix, self.plugin.name)
        if path in frame.memo:
            value = frame.memo[path]
        else:
            start = time.perf_counter()
            try:
                value = self.plugin.process(data, frame.context)
            except Exception as exc:
                if frame.record is not None:
                    frame.record(self.plugin.name, time.perf_counter() - start, False)
                raise PluginError(self.plugin.name, frame.context.frame) from exc
            if frame.record is not None:
                frame.record(self.plugin.name, time.perf_counter() - start, True)
            frame.memo[path] = value
        if value is None:  # nothing for this frame: the subtree's outputs are empty too
            for below, _ in self.walk(prefix):
                frame.memo.setdefault(below, None)
            return
        for child in self.children:
            child.run(value, frame, path)


@dataclass(frozen=True)
class ProfilePlan:
    """A built profile: its composition tree and the path of its output node."""

    name: str
    tree: Composite
    output: Path


@dataclass(frozen=True)
class Frame:
    """What one run produced: the selection it used and each service's output."""

    index: int
    stamp: float
    profiles: Mapping[str, str]
    outputs: Mapping[str, Any]


def _error(record: Record, message: str, attr: str | None = None) -> ConfigError:
    return ConfigError.of(record, message, attr)


class Topology:
    """The SPT of one Smart Resource (§3.2.2): its plugin instances, its profiles, and the active selection.

    Built from the SmartResource record and the registry (category ``plugin``, by kind): an unknown
    kind, a bad Param or a class that is not a ProcessingPlugin is a ConfigError at the Plugin; a
    Use naming no plugin, or an output not in its profile's tree, is a ConfigError there too.
    ``run()`` is called by one processing thread (the triple buffer's); ``select()``, ``release()``
    and ``stats()`` may be called from any thread.
    """

    def __init__(self, resource: SmartResource, registry: Registry | None = None) -> None:
        registry = registry or default_registry()
        self.resource = resource
        self.name = resource.name
        self.plugins: dict[str, ProcessingPlugin] = {}
        for record in resource.plugins:
            if record.name in self.plugins:
                raise _error(record, f"plugin {record.name!r} is declared twice", "name")
            self.plugins[record.name] = self._make(record, registry)
        self.profiles: dict[str, ProfilePlan] = {p.name: self._plan(p) for p in resource.profiles}
        self._lock = threading.Lock()
        self._requested: dict[str, str] = {}
        self._private: set[str] = set()
        self._frames = 0
        self._stats: dict[str, PluginStats] = {name: PluginStats() for name in self.plugins}

    @staticmethod
    def _make(record: Plugin, registry: Registry) -> ProcessingPlugin:
        cls = registry.resolve("plugin", record.kind, record)
        if not issubclass(cls, ProcessingPlugin):
            raise _error(record, f"plugin kind {record.kind!r} is not a ProcessingPlugin", "kind")
        try:
            return cls(record)
        except ValueError as exc:  # ParamError, or a plugin's own check
            raise _error(record, str(exc)) from None

    def _node(self, use: Use) -> Composite:
        plugin = self.plugins.get(use.plugin)
        if plugin is None:
            known = ", ".join(sorted(self.plugins)) or "none"
            raise _error(use, f"no plugin {use.plugin!r} in resource {self.name!r} (plugins: {known})", "plugin")
        return Composite(plugin, [self._node(child) for child in use.uses])

    def _plan(self, profile: Profile) -> ProfilePlan:
        tree = self._node(profile.root)
        wanted = profile.output_plugin()
        # With a plugin used twice in one tree, the first in execution order is the output.
        output = next((path for path, node in tree.walk() if node.plugin.name == wanted), None)
        if output is None:
            raise _error(profile, f"output plugin {wanted!r} is not in profile {profile.name!r}", "output")
        return ProfilePlan(profile.name, tree, output)

    # ------------------------------------------------------------------ lifecycle

    def setup(self) -> None:
        """Set every plugin up (all profiles, so that a later switch needs no set-up mid-stream)."""
        done: list[ProcessingPlugin] = []
        try:
            for plugin in self.plugins.values():
                plugin.setup()
                done.append(plugin)
        except BaseException:
            for plugin in reversed(done):
                plugin.stop()
            raise

    def stop(self) -> None:
        """Stop every plugin in reverse order; the first failure is raised once all have been stopped."""
        failure: Exception | None = None
        for plugin in reversed(list(self.plugins.values())):
            try:
                plugin.stop()
            except Exception as exc:
                failure = failure or exc
        if failure is not None:
            raise failure

    def state(self) -> dict[str, dict[str, Any]]:
        """The non-empty states of the plugins, by name (for delegation)."""
        return {name: s for name, plugin in self.plugins.items() if (s := plugin.state())}

    def restore(self, states: Mapping[str, Mapping[str, Any]]) -> None:
        """Give each named plugin back its state (after delegation)."""
        for name, state in states.items():
            self.plugins[name].restore(state)

    # ------------------------------------------------------------------ selection

    def select(self, service: str, profile: str, *, share: bool = True) -> None:
        """Run ``profile`` for ``service`` from the next frame on (``service`` is any client key).

        ``share=False`` makes ``service`` a *replica*: its tree runs on a memo of its own below the
        root, so two replicas on one profile process the frame twice (the thesis' replicated
        services of §7.2); only the root (the acquisition) stays shared.
        """
        with self._lock:
            if share:
                self._private.discard(service)
            else:
                self._private.add(service)
        self.select_all({service: profile})

    def select_all(self, selection: Mapping[str, str]) -> None:
        """Several services switched together: the same frame sees all the changes or none."""
        for profile in selection.values():
            if profile not in self.profiles:
                known = ", ".join(self.profiles) or "none"
                raise ValueError(f"resource {self.name!r} has no profile {profile!r} (profiles: {known})")
        with self._lock:
            self._requested.update(selection)

    def release(self, service: str) -> None:
        """Stop producing output for ``service`` from the next frame on."""
        with self._lock:
            self._requested.pop(service, None)
            self._private.discard(service)

    def selection(self) -> dict[str, str]:
        """The selection the next frame will run, service → profile."""
        with self._lock:
            return dict(self._requested)

    def paths(self, profiles: Iterable[str]) -> list[Path]:
        """The nodes a frame runs for these profiles, each once, in execution order."""
        seen: dict[Path, None] = {}
        for name in dict.fromkeys(profiles):
            for path, _ in self.profiles[name].tree.walk():
                seen.setdefault(path, None)
        return list(seen)

    # ------------------------------------------------------------------ frames

    def run(self, data: Any, stamp: float | None = None) -> Frame:
        """Process one frame for every active service; a plugin failure raises PluginError."""
        with self._lock:
            selection = dict(self._requested)
            private = self._private & selection.keys()
            index = self._frames
            self._frames += 1
        frame = FramePass(Context(index, time.monotonic() if stamp is None else stamp, self.name), record=self._tally)
        for name in dict.fromkeys(p for s, p in selection.items() if s not in private):
            self.profiles[name].tree.run(data, frame)
        outputs = {s: frame.memo[self.profiles[p].output] for s, p in selection.items() if s not in private}
        for service in sorted(private):
            plan = self.profiles[selection[service]]
            own = FramePass(frame.context, {k: v for k, v in frame.memo.items() if len(k) == 1}, frame.record)
            plan.tree.run(data, own)
            root = (plan.tree.plugin.name,)
            frame.memo.setdefault(root, own.memo[root])
            outputs[service] = own.memo[plan.output]
        return Frame(index, frame.context.stamp, selection, {s: outputs[s] for s in selection})

    @property
    def frames(self) -> int:
        """Frames run through the topology so far."""
        with self._lock:
            return self._frames

    def _tally(self, plugin: str, elapsed: float, ok: bool) -> None:
        with self._lock:
            stats = self._stats[plugin]
            stats.calls += 1
            stats.errors += 0 if ok else 1
            stats.total += elapsed
            stats.last = elapsed
            stats.max = max(stats.max, elapsed)

    def stats(self) -> dict[str, PluginStats]:
        """A copy of the per-plugin statistics."""
        with self._lock:
            return {name: dataclasses.replace(s) for name, s in self._stats.items()}

    def reset_stats(self) -> None:
        """Zero every plugin's call and time counters."""
        with self._lock:
            self._stats = {name: PluginStats() for name in self.plugins}
