"""Processing-function plugins for the ``<Function plugin="…">`` adaptation step.

- ``function.wrap-angle``: an angle wrapped into one turn (for headings and joint encoders);
- ``function.outlier-reject``: drops single-sample outliers (the example of adaptation_chain.xml).

Each class is built with the step's Params and reports bad ones as ParamError.
"""

from __future__ import annotations

import math
import statistics
from collections import deque
from collections.abc import Sequence

from ckmconf.model import Param
from runtime.kernel.adaptation import Identity, Step
from runtime.kernel.interfaces import AdaptationFunction, ParamError, read_params
from runtime.verification.manifest import P, Params


class WrapAngle(Step):
    """The angle brought into [center − period/2, center + period/2).

    Params: ``period`` (default 2π, so radians; 360 for degrees) and ``center`` (default 0, so
    −π…π). Wrapping is an idempotent projection, so in an inverse chain it acts as itself.
    """

    PARAMS = Params(
        P("period", 2.0 * math.pi, "One turn (2π for radians, 360 for degrees).", above=0.0),
        P("center", 0.0, "Centre of the output interval."),
    )

    def __init__(self, params: Sequence[Param] = ()) -> None:
        values = read_params(params, self.PARAMS, owner="function 'wrap-angle'")
        if not values["period"] > 0.0:
            raise ParamError(f"function 'wrap-angle': parameter 'period' = {values['period']} must be greater than 0")
        self.period: float = values["period"]
        self.low: float = values["center"] - self.period / 2.0

    def __call__(self, value: float, now: float) -> float:
        """``value`` wrapped into [center − period/2, center + period/2)."""
        wrapped = self.low + (value - self.low) % self.period
        return self.low if wrapped >= self.low + self.period else wrapped  # rounding can land on the top

    def inverse(self) -> AdaptationFunction:
        """Itself: wrapping is an idempotent projection."""
        return self


class OutlierReject(Step):
    """A sample further than ``sigma`` standard deviations from the mean of the last accepted ones is replaced.

    It is replaced by the last accepted value. Params: ``sigma`` (default 3), ``window`` (accepted
    samples kept, default 10; rejection starts once 3 are kept) and ``maxRejects`` (default 3):
    after that many rejections in a row the signal has really moved, so the sample is accepted
    and the window restarts from it. In an inverse chain it passes values through.
    """

    PARAMS = Params(
        P("sigma", 3.0, "Rejection threshold in standard deviations of the window.", above=0.0),
        P("window", 10, "Accepted samples kept (rejection starts once 3 are kept).", above=2),
        P("maxRejects", 3, "Rejections in a row after which the sample is accepted.", above=0),
    )

    def __init__(self, params: Sequence[Param] = ()) -> None:
        owner = "function 'outlier-reject'"
        values = read_params(params, self.PARAMS, owner=owner)
        for name, low in (("sigma", 0.0), ("window", 2), ("maxRejects", 0)):
            if not values[name] > low:
                raise ParamError(f"{owner}: parameter {name!r} = {values[name]} must be greater than {low}")
        self.sigma: float = values["sigma"]
        self.max_rejects: int = values["maxRejects"]
        self.accepted: deque[float] = deque(maxlen=values["window"])
        self.rejects = 0

    def __call__(self, value: float, now: float) -> float:
        """``value``, or the last accepted value when ``value`` is an outlier of the window."""
        if len(self.accepted) >= 3 and self.rejects < self.max_rejects:
            mean = statistics.fmean(self.accepted)
            if abs(value - mean) > self.sigma * statistics.pstdev(self.accepted, mean):
                self.rejects += 1
                return self.accepted[-1]
        if self.rejects >= self.max_rejects:
            self.accepted.clear()
        self.rejects = 0
        self.accepted.append(value)
        return value

    def reset(self) -> None:
        """Forget the accepted values and the count of rejects."""
        self.accepted.clear()
        self.rejects = 0

    def inverse(self) -> AdaptationFunction:
        """The identity (accepted samples pass unchanged)."""
        return Identity()
