"""The wire protocol of SPT plugin delegation (§3.1.2.5–6, "code delegation"): messages, checks, errors.

What moves is data, never code: the plugin's registered kind, its ``<Plugin>`` record as plain
data (name, kind, params) and its state (``ProcessingPlugin.state()``), with numpy arrays encoded
by ``codec`` — never pickles. The receiving node must have the kind registered, or it refuses.

Protocol (every message a msgpack-able dict with an ``op``; ``id`` names one delegation):

- OFFER ``{op, id, from, reply, plugin: {name, kind, params: [[name, value]…]}, state}`` giver →
  ``/ckm/plugin-delegation/TAKER``. The host builds the plugin, ``setup()``s it and restores the
  offered state (so a state it cannot take is refused now, not mid-stream).
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

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ckmconf.model import Param
from ckmconf.model.resources import Plugin

from ..network.api import TopicQoS

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


def describe(record: Plugin) -> dict[str, Any]:
    """A Plugin record as plain data."""
    return {"name": record.name, "kind": record.kind, "params": [[p.name, p.value] for p in record.params]}


def plugin_record(spec: Any) -> Plugin:
    """The Plugin record a description stands for; BadMessage if it is not one."""
    if not isinstance(spec, dict):
        raise BadMessage("field 'plugin' must be a dict")
    params = get_field(spec, "params", list)
    if len(params) > 1000 or not all(
        isinstance(p, list) and len(p) == 2 and all(isinstance(s, str) and len(s) <= 4096 for s in p) for p in params
    ):
        raise BadMessage("field 'params' must be a list of [name, value] strings")
    return Plugin(
        name=get_field(spec, "name", str),
        kind=get_field(spec, "kind", str),
        params=tuple(Param(name=n, value=v) for n, v in params),
    )
