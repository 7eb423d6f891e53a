"""A run's clock scaled against the wall clock (issue J point 5: simulated time, ``ckm-run --time-scale``).

A simulated laboratory may need more CPU than the machine has: the use case's renders, loops and
recognitions need several cores on a two-core machine. With a time scale ``s`` < 1 every process of
a run (ckm-run, its partition processes, the world server) reads a clock that advances ``s``
seconds per wall second: ``time.monotonic``, ``time.time``, ``time.perf_counter`` and the CPU
clocks (``time.process_time``, ``time.thread_time``) are scaled alike, and ``time.sleep`` sleeps
the scaled duration. Periods, deadlines, timeouts, stamps, CPU shares and the physics all live on
that one clock, so a run behaves as it would on a machine ``1/s`` times faster; its report states
the scale (the real-time factor is ``s`` at best).

Every process installs the same scale from the environment (``CKM_TIME_SCALE``) around the same
origin (``CKM_TIME_ORIGIN``: a monotonic and a wall reading taken once by the run), so stamps and
deadlines agree across processes. The origin is the same CLOCK_MONOTONIC instant in every process
of the machine. Timed waits of ``threading`` (``Condition.wait``, hence ``Event.wait``, ``Timer``,
``queue.Queue.get``, ``Semaphore.acquire``) wait the scaled duration too: a loop pacing itself with
``event.wait(period)`` keeps its period on the run's clock (unscaled it ran ``1/s`` times too often,
and a scheduler spun the rest of each period, busy, before every release). Lock and socket
timeouts keep the wall clock.

``ckm-run --lockstep STEP`` puts a run on a clock that is no scale of the wall clock at all: it
advances only when every participating thread waits (:mod:`runtime.lockstep`, D190); ``install``
takes that one when ``CKM_LOCKSTEP`` names it.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, MutableMapping

from . import lockstep

SCALE_VARIABLE = "CKM_TIME_SCALE"
ORIGIN_VARIABLE = "CKM_TIME_ORIGIN"
_REAL: dict[str, Callable[..., float]] = {}  # the wall clocks, kept before any patch
_installed: float | None = None


def _real(name: str) -> Callable[..., float]:
    function: Callable[..., float] = _REAL.get(name) or getattr(time, name)
    return function


def parse_scale(text: str) -> float:
    """The scale of ``--time-scale`` or ``CKM_TIME_SCALE``: a number in (0, 1]."""
    try:
        scale = float(text)
    except ValueError:
        raise ValueError(f"time scale {text!r} is not a number") from None
    if not 0.0 < scale <= 1.0:
        raise ValueError(f"time scale {text!r} is not in (0, 1]: a run may be slowed, never sped up")
    return scale


def environment(scale: float) -> dict[str, str]:
    """The variables that make a process (and its children) run on ``scale``, from now."""
    origin = f"{_real('monotonic')()!r} {_real('time')()!r} {_real('perf_counter')()!r}"
    return {SCALE_VARIABLE: repr(parse_scale(repr(scale))), ORIGIN_VARIABLE: origin}


def install(env: MutableMapping[str, str] | None = None) -> float | None:
    """Scale this process's clocks as ``env`` (default: ``os.environ``) says; the scale, or None.

    Idempotent; a process whose environment names no scale keeps the wall clock. Raises
    ValueError for a malformed scale or origin, naming the variable.
    """
    global _installed
    env = os.environ if env is None else env
    if lockstep.install(env) is not None:
        if env.get(SCALE_VARIABLE):
            raise ValueError(f"{SCALE_VARIABLE} and {lockstep.VARIABLE}: a run is scaled or in lock-step, not both")
        return None
    text = env.get(SCALE_VARIABLE)
    if not text:
        return None
    scale = parse_scale(text)
    if _installed is not None:
        if _installed != scale:
            raise ValueError(f"{SCALE_VARIABLE}: this process already runs at scale {_installed}, not {scale}")
        return scale
    try:
        mono0, wall0, perf0 = (float(x) for x in env[ORIGIN_VARIABLE].split())
    except (KeyError, ValueError):
        raise ValueError(f"{ORIGIN_VARIABLE} must hold three numbers (monotonic, wall, perf_counter origins)") from None
    for name in ("monotonic", "time", "perf_counter", "process_time", "thread_time", "sleep"):
        _REAL[name] = getattr(time, name)
    real_mono, real_wall, real_perf = _REAL["monotonic"], _REAL["time"], _REAL["perf_counter"]
    real_process, real_thread, real_sleep = _REAL["process_time"], _REAL["thread_time"], _REAL["sleep"]

    def sleep(seconds: float) -> None:
        real_sleep(max(0.0, seconds) / scale)

    scaled: dict[str, Callable[..., object]] = {
        "monotonic": lambda: mono0 + scale * (real_mono() - mono0),
        "time": lambda: wall0 + scale * (real_wall() - wall0),
        "perf_counter": lambda: perf0 + scale * (real_perf() - perf0),
        "process_time": lambda: scale * real_process(),
        "thread_time": lambda: scale * real_thread(),
        "sleep": sleep,
    }
    for name, function in scaled.items():
        setattr(time, name, function)
    wall_wait = threading.Condition.wait

    def wait(self: threading.Condition, timeout: float | None = None) -> bool:
        return wall_wait(self, None if timeout is None else max(0.0, timeout) / scale)

    threading.Condition.wait = wait  # type: ignore[method-assign]
    _installed = scale
    return scale


def scale() -> float:
    """The scale this process runs at (1.0: the wall clock; 0.0 in lock-step, whose clock has no
    rate against the wall clock: a scheduler spins no wall time before a release)."""
    if lockstep.active() is not None:
        return 0.0
    return _installed or 1.0


def wall(seconds: float) -> float:
    """How many wall seconds ``seconds`` of this process's clock take (for waits in the standard
    library; in lock-step unknown beforehand: ``seconds``)."""
    return seconds / (scale() or 1.0)
