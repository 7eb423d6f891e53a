"""Private networks take their ports below the kernel's ephemeral range."""

from __future__ import annotations

import random

from runtime.network.ports import SPAN, ephemeral_low, private_base


def test_private_bases_keep_their_span_below_the_ephemeral_range() -> None:
    rng = random.Random(7)
    low = ephemeral_low()
    bases = {private_base(rng) for _ in range(500)}
    assert all(b >= 10000 and b + SPAN <= low and b % SPAN == 10000 % SPAN for b in bases)
    assert len(bases) > 100  # enough room that two private networks rarely meet
