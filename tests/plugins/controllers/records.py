"""A Controller record for unit tests, built in code (no XML): kind, period, horizon and params."""

from __future__ import annotations

from ckmconf.model import Param
from ckmconf.model.kernel import Controller as ControllerRecord


def controller_record(kind: str, period: float, horizon: int, **params: object) -> ControllerRecord:
    return ControllerRecord(
        name=kind,
        kind=kind,
        period=period,
        horizon=horizon,
        params=tuple(Param(name=k, value=str(v)) for k, v in params.items()),
    )
