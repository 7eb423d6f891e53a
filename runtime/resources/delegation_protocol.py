"""The wire protocol of SPT plugin delegation (§3.1.2.5–6, "code delegation"): messages, checks, errors.

What moves is data, never code: the plugin's ``<Plugin>`` as configuration text and its state
(``ProcessingPlugin.state()``), with numpy arrays encoded by ``codec`` — never pickles. The text is
what a controller's delegation carries (decision D183, D195): a ``<Part>`` written by ckmconf's
binding, holding the giver's ``<SmartResource>`` reduced to the plugin and, since the schema wants
one, the services it serves by name, and the giver's ``<Node>`` it names, empty (:func:`describe`);
the taker reads it with :func:`ckmconf.load_bytes` (schema, records, semantic checks; no
``<Include>``) and checks the kind and its Params as ``verify`` does
(:func:`runtime.verification.manifest.param_problems`), so a bad offer is refused with the message
``ckm-validate`` would print, at ``<delegation from NODE>:LINE:COL: XPATH`` (:func:`plugin_of`).
The receiving node must have the kind registered, or it refuses.

Protocol (every message a msgpack-able dict with an ``op``; ``id`` names one delegation):

- OFFER ``{op, id, from, reply, plugin: TEXT, state}`` giver → ``/ckm/plugin-delegation/TAKER``.
  The host builds the plugin, ``setup()``s it and restores the offered state (so a state it cannot
  take is refused now, not mid-stream).
- READY ``{op, id}`` or REFUSE ``{op, id, reason}`` host → ``reply`` (a topic of the giver's).
- GO ``{op, id, seq, frame, stamp, resource, data, state}``: the first call after READY; the host
  restores ``state`` (the giver's state after its last local call), then processes like PROCESS.
- PROCESS ``{op, id, seq, frame, stamp, resource, data}`` → RESULT ``{op, id, seq, result, state}``
  or ERROR ``{op, id, seq, reason}``.
- RELEASE ``{op, id}`` → RELEASED ``{op, id, state}``: the host stops and drops the plugin.

The taker side is :class:`runtime.resources.plugin_host.PluginHost`, the giver side
:class:`runtime.resources.delegation.DelegatedPlugin`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ckmconf.checks.report import Reporter
from ckmconf.errors import ConfigError
from ckmconf.fragment import FRAGMENT_LIMITS
from ckmconf.loader import load_bytes
from ckmconf.model import Node
from ckmconf.model.resources import Plugin, Service, SmartResource
from ckmconf.model.system import Content, Part
from ckmconf.schema import SUPPORTED_MAJOR
from ckmconf.source import parse_bytes
from ckmconf.writer import dumps

from ..network.api import TopicQoS
from ..registry import Registry
from ..verification.manifest import param_problems

PREFIX = "/ckm/plugin-delegation/"
MAX_NAME = 256


def channel(node: str) -> TopicQoS:
    """The topic a node's PluginHost listens on."""
    return TopicQoS(f"{PREFIX}{node}", "plugin-delegation")


class DelegationError(RuntimeError):
    """A delegation that could not happen; the plugin keeps running locally."""


class DelegationRefused(DelegationError):
    """The taker refused the plugin (unknown kind, bad params, failed setup…)."""


@dataclass(frozen=True)
class DelegationEvent:
    """delegated, delegation-refused, delegation-timeout, delegation-fallback (an alarm), recalled."""

    kind: str
    plugin: str
    peer: str
    reason: str = ""
    time: float = field(default_factory=time.time)


class BadMessage(ValueError):
    """A delegation message that is not what the protocol says."""


def get_field(message: Mapping[str, Any], key: str, kind: type | tuple[type, ...] = object) -> Any:
    """``message[key]`` checked against ``kind`` (a bool is not a number here)."""
    if key not in message:
        raise BadMessage(f"field {key!r} is missing")
    value = message[key]
    if not isinstance(value, kind) or (isinstance(value, bool) and kind is not object):
        raise BadMessage(f"field {key!r} has type {type(value).__name__}")
    if isinstance(value, str) and len(value) > MAX_NAME:
        raise BadMessage(f"field {key!r} is longer than {MAX_NAME} characters")
    return value


_CARRIED = ("nodes", "resources", "includes", "loc")
"""What a plugin fragment may hold (``<Include>`` is refused by the loader itself)."""


def describe(record: Plugin, giver: str, resource: SmartResource | None = None) -> str:
    """A plugin as configuration text: a ``<Part>`` holding the giver's empty ``<Node>`` and
    ``resource`` (the giver's) reduced to the plugin and the services whose scenarios use it, by
    name (all of them if none does).

    A plugin wrapped outside a resource travels in a resource named after ``giver``, with one
    service named after the plugin: the schema wants a ``<SmartResource>`` to have a ``<Service>``.
    """
    services: tuple[Service, ...] = (Service(name=record.name),)
    name = giver
    if resource is not None:
        name = resource.name
        profiles = {p.name for p in resource.profiles if record.name in p.root.plugins()}
        using = [s for s in resource.services if any(c.profile in profiles for c in s.scenarios)]
        services = tuple(Service(name=s.name) for s in using or resource.services) or services
    reduced = SmartResource(name=name, node=giver, plugins=(dataclasses.replace(record, loc=None),), services=services)
    part = Part(version=f"{SUPPORTED_MAJOR}.0", nodes=(Node(name=giver),), resources=(reduced,))
    return dumps(part).decode("utf-8")


def plugin_of(text: Any, giver: str, registry: Registry) -> tuple[Plugin, type[Any]]:
    """The Plugin record an offer describes and its class, checked as ``ckm-validate`` checks a file.

    Raises:
        ConfigError: not text; text the loader refuses; a fragment that is not one SmartResource
            holding one Plugin; a kind the registry lacks (at ``@kind``) or Params its declaration
            refuses (at the Param) — located in ``<delegation from GIVER>``.
    """
    origin = f"<delegation from {giver}>"
    if not isinstance(text, str | bytes):
        raise ConfigError(origin, 1, 1, "/", f"a plugin description is configuration text, not {type(text).__name__}")
    data = text.encode("utf-8") if isinstance(text, str) else text
    system = load_bytes(data, origin, limits=FRAGMENT_LIMITS, includes=False)
    for part in dataclasses.fields(Content):
        if part.name not in _CARRIED and getattr(system, part.name) not in (None, ()):
            raise ConfigError.of(system, f"a plugin fragment holds a Node and one SmartResource, not {part.name}")
    bare = [dataclasses.replace(n, loc=None) == Node(name=n.name, kind=n.kind) for n in system.nodes]
    if len(system.resources) != 1 or len(system.resources[0].plugins) != 1 or bare != [True]:
        raise ConfigError.of(
            system, "a plugin fragment holds its giver's empty Node and exactly one SmartResource with one Plugin"
        )
    record = system.resources[0].plugins[0]
    cls = registry.resolve("plugin", record.kind, record)  # ConfigError at @kind
    problems = param_problems(cls, record.params, f"plugin kind {record.kind!r}")
    if problems:
        reporter = Reporter({origin: parse_bytes(origin, data, FRAGMENT_LIMITS)})
        first = problems[0]
        reporter.error(first.param or record, first.message, first.attr, first.offset)
        raise reporter.errors[0]
    return record, cls
