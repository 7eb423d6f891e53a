"""Bounded waiting for tests: poll a condition until it holds or a timeout passes (never an unbounded wait)."""

from __future__ import annotations

import time
from collections.abc import Callable


def until(condition: Callable[[], bool], timeout: float = 10.0, interval: float = 0.05) -> bool:
    """Poll ``condition`` every ``interval`` s for at most ``timeout`` s; its answer, checked once more at the end."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(interval)
    return condition()
