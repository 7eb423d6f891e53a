"""Controller records with Inputs and Outputs, built in code (no XML), for the multi-output controllers."""

from __future__ import annotations

from collections.abc import Sequence

from ckmconf.model import Param
from ckmconf.model.kernel import Controller as ControllerRecord
from ckmconf.model.kernel import ControllerInput, ControllerOutput


def record(
    kind: str,
    period: float,
    inputs: Sequence[tuple[str, str | None]],
    outputs: Sequence[str | tuple[str, str]],
    horizon: int = 10,
    /,
    **params: object,
) -> ControllerRecord:
    """A ``<Controller>`` reading ``inputs`` (topic, role) and writing ``outputs`` (topic, or (topic, role))."""
    return ControllerRecord(
        name=kind,
        kind=kind,
        period=period,
        horizon=horizon,
        params=tuple(Param(name=k, value=str(v)) for k, v in params.items()),
        inputs=tuple(ControllerInput(topic=t, role=r) for t, r in inputs),
        outputs=tuple(
            ControllerOutput(topic=o) if isinstance(o, str) else ControllerOutput(topic=o[0], role=o[1])
            for o in outputs
        ),
    )
