"""<Param> (schemas/common.xsd ParamType): a named setting of a plugin, backend, controller, behavior or service."""

from __future__ import annotations

from dataclasses import dataclass

from ..binding import Record, attr


@dataclass(frozen=True, kw_only=True)
class Param(Record):
    """<Param>: a named setting handed to a plugin, backend, controller or behavior."""

    TAG = "Param"
    name: str = attr()
    value: str = attr()


def params_dict(params: tuple[Param, ...]) -> dict[str, str]:
    """``<Param name value>`` elements as {name: value text} (conversion is the kind's manifest's job)."""
    return {p.name: p.value for p in params}
