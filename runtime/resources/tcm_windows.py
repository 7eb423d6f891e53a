"""The measure windows a Task Configuring Module rates its scenarios on (thesis §4.2.1.2–4.2.1.3, eq. 4.4–4.5).

Every condition of the TCM (a scenario's policy, a client's requirement) is evaluated over the
last ``window`` samples of its measure (eq. 4.4). :class:`MeasureWindows` keeps one window per
measure, as long as the longest condition on it needs:

- **Combined measures** (``<CombinedMeasure>``, eq. 4.5): a condition on one is evaluated on the
  convolution of its components' last ``window`` samples, each component observed under its own
  name (docs/decisions.md D72).
- **Requirements** are judged on the samples measured after they were set (D201), see
  :meth:`MeasureWindows.required_source`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

from .quality import DEFAULT_WINDOW, Distribution, FloatArray, MeasureWindow, PolicyEvaluator, combined_distribution

Source = MeasureWindow | Distribution | tuple[()]
"""What a condition is evaluated on: a measure's window, a combined measure's sum, or nothing yet."""


class MeasureWindows:
    """The windows of the measures a TCM's conditions name, and the sums of its combined measures (eq. 4.4–4.5)."""

    def __init__(
        self,
        combined: Mapping[str, Sequence[str]] | None = None,
        resolutions: Mapping[str, float | None] | None = None,
        resolution: float | None = None,
    ) -> None:
        self.combined = {name: tuple(parts) for name, parts in (combined or {}).items()}
        self.resolutions = {name: (resolutions or {}).get(name) or resolution for name in self.combined}
        self._windows: dict[str, MeasureWindow] = {}
        self._required_since: dict[str, int] = {}

    def need(self, measure: str, window: int) -> None:
        """Keep at least ``window`` samples of ``measure`` (of each component when it is combined)."""
        for name in self.combined.get(measure, (measure,)):
            current = self._windows.get(name)
            if current is None or current.window < window:
                grown = MeasureWindow(window)
                if current is not None:
                    grown.extend(current.last())
                self._windows[name] = grown

    def observe(self, measure: str, value: float) -> None:
        """A new sample of a measure (a component of a combined measure feeds the sum)."""
        if measure not in self._windows:
            self.need(measure, DEFAULT_WINDOW)
        self._windows[measure].push(value)

    def source(self, measure: str, window: int) -> Source:
        """The samples a condition on ``measure`` is evaluated on: its window, or the convolution (eq. 4.5)."""
        parts = self.combined.get(measure)
        if parts is None:
            return self._windows[measure]
        windows = [self._windows[p].last(window) for p in parts]
        if any(w.size == 0 for w in windows):
            return ()
        return combined_distribution(windows, self.resolutions[measure])

    def requirements_set(self, measures: Iterable[str]) -> None:
        """New requirements on ``measures``: from now on they are judged on the samples that follow (D201)."""
        self._required_since = {
            measure: window.pushed
            for measure in measures
            if isinstance(window := self._windows.get(measure), MeasureWindow)
        }

    def required_source(self, evaluator: PolicyEvaluator) -> Source | FloatArray:
        """A requirement's samples: those measured since it was set (D201), else its measure's window."""
        source = self.source(evaluator.measure, evaluator.window)
        since = self._required_since.get(evaluator.measure)
        if since is None or not isinstance(source, MeasureWindow):
            return source
        return source.last(min(evaluator.window, source.pushed - since))
