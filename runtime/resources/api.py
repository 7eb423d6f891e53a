"""The service API of a Smart Resource (thesis §4.3, Fig. 4.6): topic names and message shapes.

Every service exposes, next to its data topics:

- ``/RESOURCE/SERVICE/config`` (clients → service): ``connect``, ``configure`` and ``disconnect``
  requests carrying the client's parameters and requested quality bounds (its QR);
- ``/RESOURCE/SERVICE/quality`` (service → clients): the acknowledgement of every request, the
  measures and active scenario of each client's instance every TCM period, and an ``event`` on
  every scenario change;
- ``/RESOURCE/SERVICE/alarms`` (service → clients): an alarm when no scenario meets a client's
  requirements, and its clearing;

and announces itself on :data:`DIRECTORY_TOPIC` so any client on the network can discover it.
The names may be overridden per service in the configuration (``configTopic`` …). A client's
instance publishes its data on ``OUTPUT_TOPIC/CLIENT``; the service's own instance (client
``""``) on the configured output topics. Every message is a msgpack-able dict with a ``type``.

Requests are untrusted network input: :func:`parse_request` checks every field and returns the
errors it found, each naming the field; nothing partly valid is applied.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ckmconf.model.resources import Parameter, Service, SmartResource

from ..network.api import TopicQoS

DIRECTORY_TOPIC = "/ckm/services"
CLIENT_ID = re.compile(r"[A-Za-z0-9_.-]{1,64}\Z")
OPS = ("connect", "configure", "disconnect")
MAX_REQUIREMENTS = 32


@dataclass(frozen=True)
class Bounds:
    """A requested quality bound on one measure (the QR of eq. 4.9); duck-types QualityBounds."""

    measure: str
    lower: float | None = None
    upper: float | None = None
    probability: float = 0.95

    def to_message(self) -> dict[str, Any]:
        """The bounds as the ``requirements`` entry of a configure request (§4.3)."""
        return {"measure": self.measure, "lower": self.lower, "upper": self.upper, "probability": self.probability}


@dataclass(frozen=True)
class Request:
    """A validated config-topic request."""

    op: str
    client: str
    request_id: int
    parameters: Mapping[str, Any]
    requirements: tuple[Bounds, ...] | None  # None: leave the current ones


def topics(resource: SmartResource, service: Service) -> dict[str, TopicQoS]:
    """The config, quality and alarm topics of a service (reliable, with some history for late readers)."""
    names = resource.topics_of(service)
    return {
        "config": TopicQoS(names["config"], "ckm/service-config", history=32),
        "quality": TopicQoS(names["quality"], "ckm/service-quality", history=64),
        "alarms": TopicQoS(names["alarms"], "ckm/service-alarm", history=32),
    }


def client_topic(topic: str, client: str) -> str:
    """Where a client's instance publishes what the service publishes on ``topic``."""
    return topic if not client else f"{topic.rstrip('/')}/{client}"


def describe(resource: SmartResource, service: Service, node: str) -> dict[str, Any]:
    """The directory entry of a service: enough for a client to configure and consume it."""
    names = resource.topics_of(service)
    return {
        "type": "service",
        "resource": resource.name,
        "service": service.name,
        "node": node,
        "function": service.function or "",
        "inputs": {i.name: i.topic for i in service.inputs},
        "outputs": {o.name: o.topic for o in service.outputs},
        **names,
        "parameters": [
            {"name": p.name, "type": p.type, "default": p.default, "min": p.min, "max": p.max, "values": p.values}
            for p in service.parameters
        ],
        "measures": [
            {"name": m.name, "kind": m.kind, "domain": m.domain, "unit": m.unit, "source": m.source}
            for m in service.measures
        ],
        "combined": [{"name": c.name, "measures": list(c.measures), "unit": c.unit} for c in service.combined],
        "scenarios": [
            {
                "name": s.name,
                "profile": s.profile,
                "weight": s.weight,
                "policies": [
                    {"measure": p.measure, "lower": p.lower, "upper": p.upper, "probability": p.probability}
                    for p in s.policies
                ],
            }
            for s in service.scenarios
        ],
    }


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def check_parameter(parameter: Parameter, value: Any) -> tuple[Any, str | None]:
    """``value`` converted to the parameter's type, or an error saying why it is refused."""
    name = f"parameter {parameter.name!r}"
    if parameter.type == "bool":
        return (value, None) if isinstance(value, bool) else (None, f"{name} must be true or false, not {value!r}")
    if parameter.type == "string":
        ok = isinstance(value, str) and len(value) <= 4096
        return (value, None) if ok else (None, f"{name} must be a string of at most 4096 characters")
    if parameter.type == "enum":
        allowed = parameter.values or ()
        if value in allowed:
            return value, None
        return None, f"{name} = {value!r} is not one of {', '.join(allowed)}"
    number = _number(value)
    if number is None or (parameter.type == "int" and not float(number).is_integer()):
        return None, f"{name} must be a finite {parameter.type}, not {value!r}"
    if parameter.min is not None and number < parameter.min:
        return None, f"{name} = {value!r} is below its minimum {parameter.min:g}"
    if parameter.max is not None and number > parameter.max:
        return None, f"{name} = {value!r} is above its maximum {parameter.max:g}"
    return (int(number) if parameter.type == "int" else number), None


def typed_default(parameter: Parameter) -> Any:
    """A parameter's XML default in its type (None when it has none)."""
    raw = parameter.default
    if raw is None:
        return None
    if parameter.type == "bool":
        return raw.strip().lower() in ("true", "1")
    if parameter.type in ("int", "float"):
        number = float(raw)
        return int(number) if parameter.type == "int" else number
    return raw


def _bounds(item: Any, index: int, measures: set[str]) -> tuple[Bounds | None, list[str]]:
    where = f"requirements[{index}]"
    if not isinstance(item, Mapping):
        return None, [f"{where} must be an object with measure, lower, upper, probability"]
    errors: list[str] = []
    measure = item.get("measure")
    if measure not in measures:
        errors.append(f"{where}.measure {measure!r} is not a measure of this service ({', '.join(sorted(measures))})")
    values: dict[str, float | None] = {}
    for key in ("lower", "upper"):
        raw = item.get(key)
        values[key] = None if raw is None else _number(raw)
        if raw is not None and values[key] is None:
            errors.append(f"{where}.{key} must be a finite number or null, not {raw!r}")
    probability = _number(item.get("probability", 0.95))
    if probability is None or not 0.0 < probability <= 1.0:
        errors.append(f"{where}.probability must be in (0, 1], not {item.get('probability')!r}")
    low, high = values["lower"], values["upper"]
    if low is None and high is None and not errors:
        errors.append(f"{where} needs a lower or an upper bound")
    if low is not None and high is not None and low > high:
        errors.append(f"{where}: lower {low:g} is above upper {high:g}")
    unknown = set(item) - {"measure", "lower", "upper", "probability"}
    if unknown:
        errors.append(f"{where} has unknown fields: {', '.join(sorted(map(str, unknown)))}")
    if errors:
        return None, errors
    return Bounds(str(measure), low, high, probability or 0.95), []


def parse_request(service: Service, message: Any) -> tuple[Request | None, list[str]]:
    """A config-topic message checked against the service: the request, or the errors (never both)."""
    if not isinstance(message, Mapping):
        return None, [f"a request must be an object, not {type(message).__name__}"]
    errors: list[str] = []
    op = message.get("op")
    if op not in OPS:
        errors.append(f"op {op!r} is not one of {', '.join(OPS)}")
    client = message.get("client")
    if not isinstance(client, str) or not (client == "" or CLIENT_ID.match(client)):
        errors.append(f"client {client!r} must be 1-64 characters among A-Z a-z 0-9 _ . - (or '' for the service)")
    request_id = message.get("id", 0)
    if isinstance(request_id, bool) or not isinstance(request_id, int):
        errors.append(f"id {request_id!r} must be an integer")
        request_id = 0
    known = {p.name: p for p in service.parameters}
    parameters: dict[str, Any] = {}
    raw_parameters = message.get("parameters", {})
    if not isinstance(raw_parameters, Mapping):
        errors.append("parameters must be an object of name → value")
        raw_parameters = {}
    for name, value in raw_parameters.items():
        parameter = known.get(name)
        if parameter is None:
            errors.append(f"no parameter {name!r} (parameters: {', '.join(known) or 'none'})")
            continue
        converted, error = check_parameter(parameter, value)
        if error:
            errors.append(error)
        else:
            parameters[name] = converted
    requirements: tuple[Bounds, ...] | None = None
    raw_requirements = message.get("requirements")
    if raw_requirements is not None:
        if not isinstance(raw_requirements, list | tuple) or len(raw_requirements) > MAX_REQUIREMENTS:
            errors.append(f"requirements must be a list of at most {MAX_REQUIREMENTS} bounds")
        else:
            measures = set(service.measure_names())
            parsed = []
            for index, item in enumerate(raw_requirements):
                bounds, problems = _bounds(item, index, measures)
                errors.extend(problems)
                if bounds is not None:
                    parsed.append(bounds)
            requirements = tuple(parsed)
    if errors:
        return None, errors
    return Request(str(op), str(client), int(request_id), parameters, requirements), []


def request_id(message: Any) -> int | None:
    """The id of a refused request, when it has a usable one (so its client gets the refusal)."""
    value = message.get("id") if isinstance(message, Mapping) else None
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def preferred_scenario(service: Service, parameters: Mapping[str, Any]) -> str | None:
    """The scenario an enum parameter names when its values are scenario names (e.g. ``resolution``)."""
    names = {s.name for s in service.scenarios}
    for parameter in service.parameters:
        if parameter.type == "enum" and parameter.values and set(parameter.values) <= names:
            value = parameters.get(parameter.name)
            if value is not None:
                return str(value)
    return None
