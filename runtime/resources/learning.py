"""The soft-margin classifier of a scenario (thesis eq. 4.7 and 4.10).

Eq. 4.10 is the soft-margin SVM objective ``½‖w‖² + C Σ ξ_i``; eq. 4.7 reads a scenario's state
through ``fy``, the sign of such a classifier. One :class:`ScenarioLearner` per scenario learns,
from the TCM's recorded evaluations, whether the scenario's policies will hold if it is
activated:

- features ``x``: for each policy of the scenario, in document order, the probability of
  eq. 4.4 and the policy's quantile margin (:class:`~runtime.resources.quality.PolicyResult`),
  measured at the evaluation that activated the scenario;
- label ``y``: +1 when the scenario was not left for neglect within the TCM's horizon after
  that activation, −1 when it was.

The model is ``StandardScaler`` followed by ``sklearn.svm.SVC(kernel="linear", C=C,
class_weight="balanced")`` — the hinge-loss form of eq. 4.10 with the TCM's ``C``, the intercept
not regularised; standardising keeps ``C`` meaningful whatever the measures' units, and the
balanced class weights keep rare failures from being outvoted. The last ``max_records`` records
of each label are kept. Until both labels are present and there are ``min_records`` records
there is no model and :meth:`confidence` is 1 (the configured weight is used unchanged); the
model is refitted after every ``retrain_every`` new records (activations are rare, fits cheap).
scikit-learn is imported at the first fit only.

Feedback into eq. 4.7 (see :mod:`runtime.resources.tcm`): the decision value ``d(x)`` is mapped
onto the soft margin, ``c(x) = clip((d(x) + 1) / 2, 0, 1)`` — 1 on or beyond the positive margin,
0 on or beyond the negative margin, linear in between — and the scenario's weight becomes
``w_i · c(x)``. A scenario the model expects to fail therefore rates ``−th`` and is not usable.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np


class ScenarioLearner:
    """Recorded (features, label) pairs of one scenario and the linear soft-margin SVM (eq. 4.10) fitted to them."""

    def __init__(self, c: float = 1.0, *, min_records: int = 4, max_records: int = 200, retrain_every: int = 1) -> None:
        if c <= 0:
            raise ValueError("the soft-margin cost C must be positive")
        self.c = c
        self.min_records = min_records
        self.retrain_every = max(1, retrain_every)
        self.max_records = max_records
        self._records: dict[bool, deque[tuple[float, ...]]] = {
            True: deque(maxlen=max_records),
            False: deque(maxlen=max_records),
        }
        self._model: Any = None  # a fitted sklearn Pipeline
        self._since_fit = 0

    @property
    def records(self) -> list[tuple[tuple[float, ...], bool]]:
        """The kept records: the last ``max_records`` of each label (so a long good run does not
        push the rarer failures out of the training set)."""
        return [(f, label) for label in (True, False) for f in self._records[label]]

    @property
    def trained(self) -> bool:
        """True once an SVM was fitted (enough records of both labels), so ``fy`` is known."""
        return self._model is not None

    def record(self, features: Sequence[float], label: bool) -> None:
        """Add one labelled evaluation; refit once ``retrain_every`` new ones have arrived."""
        features = tuple(float(f) for f in features)
        kept = self.records
        if kept and len(kept[0][0]) != len(features):
            for records in self._records.values():  # the scenario's policies changed: old records no longer apply
                records.clear()
            self._model = None
        self._records[label].append(features)
        self._since_fit += 1
        if self._since_fit >= self.retrain_every or (self._model is None and self._fittable()):
            self.fit()

    def _fittable(self) -> bool:
        good, bad = len(self._records[True]), len(self._records[False])
        return good > 0 and bad > 0 and good + bad >= self.min_records

    def fit(self) -> bool:
        """Fit eq. 4.10 on the records; False (and the previous model kept) when they allow no fit."""
        self._since_fit = 0
        if not self._fittable():
            return False
        from sklearn.pipeline import make_pipeline  # imported here: only learning="svm" pays for scikit-learn
        from sklearn.preprocessing import StandardScaler
        from sklearn.svm import SVC

        records = self.records
        x = np.array([f for f, _ in records], dtype=np.float64)
        y = np.array([1 if label else -1 for _, label in records])
        model = make_pipeline(StandardScaler(), SVC(kernel="linear", C=self.c, class_weight="balanced"))
        model.fit(x, y)
        self._model = model
        return True

    def decision(self, features: Sequence[float]) -> float | None:
        """The signed distance ``d(x)`` to the separating hyperplane (positive: will hold); None untrained."""
        if self._model is None:
            return None
        x = np.array([features], dtype=np.float64)
        return float(self._model.decision_function(x)[0])

    def confidence(self, features: Sequence[float] | None) -> float:
        """``clip((d(x) + 1) / 2, 0, 1)``, the factor applied to the weight in eq. 4.7; 1 without a model."""
        if features is None:
            return 1.0
        value = self.decision(features)
        return 1.0 if value is None else float(min(1.0, max(0.0, (value + 1.0) / 2.0)))
