"""What an HFSM state's transition conditions are evaluated against (thesis §5.2–5.3, docs/decisions.md D9).

A transition's condition reads the state's behavior (``done()``, ``failed()``, ``progress``), time
(``timeout()``, ``elapsed``), the nested mission's outcome (``outcome('x')``), plan signals
(``signal('s')``), the other agents of the plan (``lost('a')``) and the services the behavior
uses (``alias.field``: an output field of the service, else one of its quality measures;
``performance``, eq. 5.1). :func:`state_environment` binds those names for one active state.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from ckmconf.expressions import Environment

from .behaviors import Behavior, BehaviorStatus


class NestedRun(Protocol):
    """A nested mission as its parent's conditions see it: its outcome."""

    @property
    def outcome(self) -> str | None:
        """Name of the final it ended in, None while it runs."""


class ActiveState(Protocol):
    """One level of the HFSM with an active state (a :class:`runtime.missions.hfsm.MissionRun`)."""

    @property
    def behavior(self) -> Behavior | None:
        """The state's behavior, None for a nested mission's state."""

    @property
    def status(self) -> BehaviorStatus:
        """The behavior's last status."""

    @property
    def child(self) -> NestedRun | None:
        """The state's nested mission, None for a behavior's state."""

    def timed_out(self) -> bool:
        """True when the state's timeout has elapsed."""

    def own_progress(self) -> float:
        """Progress of the active state, in [0, 1]."""

    def elapsed(self) -> float:
        """Seconds since the state was entered."""

    def performance(self) -> float | None:
        """SPC (eq. 5.1) of the state's behavior, None without one."""


def state_environment(run: ActiveState, received: Callable[[str], bool], lost: Callable[[str], bool]) -> Environment:
    """The condition environment of ``run``'s active state; ``received``/``lost`` answer ``signal()``/``lost()``."""
    child = run.child

    def attribute(alias: str, name: str) -> Any:
        if run.behavior is None:
            return None
        handle = run.behavior.context.services.get(alias)
        if handle is None:
            return None
        value = handle.output(name)
        return value if value is not None else handle.measures().get(name)

    return Environment(
        functions={
            "done": lambda: run.status.done or (child is not None and child.outcome is not None),
            "failed": lambda: run.status.failed,
            "timeout": run.timed_out,
            "outcome": lambda name: child is not None and child.outcome == name,
            "signal": received,
            "lost": lost,
        },
        names={"progress": run.own_progress(), "elapsed": run.elapsed(), "performance": run.performance()},
        attributes=attribute,
    )
