"""ckm-bench delegation: a running controller handed to a node in another process (§3.1.2.5–6).

One giver :class:`~runtime.kernel.node.NodeRuntime` (a PID at 50 Hz on a loopback plant) and one
idle ``ckm-run --node idle`` process on a private loopback network. Each run hands the controller
over once and times its outputs as heard on the network: the gaps between successive outputs
around the handover, in periods. The protocol's claim (runtime/kernel/delegation.py) is that no
period goes without an output (largest gap under 2 periods) and none gets two (smallest gap well
above 0), so ``max_gap_periods`` and ``min_gap_periods`` are the figures; ``overlap`` counts giver
outputs heard after the taker's first (0: the handover is atomic). The timing lives here, not in
a unit test, because shared machines stretch wall-time gaps (tests/runtime/kernel/test_delegation.py
keeps the order and ownership claims).
"""

from __future__ import annotations

import argparse
import itertools
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import TracebackType
from typing import Any

import ckmconf
from runtime.kernel.node import NodeRuntime
from runtime.network import Sample, Transport, open_transport

from .netbench import private_settings

PERIOD = 0.02
REPO = Path(__file__).resolve().parents[1]
CONFIG = """<System xmlns="urn:ckm:1" version="1.0" name="delegation">
  <Network group="{group}" discoveryPort="{dport}" basePort="{base}" portTries="48" heartbeat="0.1"/>
  <Node name="plant" kind="light">
    <HWChannel name="y" direction="in"><Param name="plant" value="p"/></HWChannel>
    <HWChannel name="u" direction="out" min="-10" max="10">
      <Param name="plant" value="p"/><Param name="gain" value="1"/><Param name="timeConstant" value="0.2"/>
    </HWChannel>
    <Topic name="y" type="float64" scope="internal"/>
    <Topic name="u" type="float64" scope="internal"/>
    <Topic name="r" type="float64" scope="internal"/>
    <Sensor name="y" channel="y" topic="y" period="0.01"/>
    <Controller name="pid" kind="pid" period="{period}" delegable="true">
      <Param name="kp" value="0.8"/><Param name="ki" value="4"/>
      <Input topic="y" role="measure"/><Input topic="r" role="setpoint"/><Output topic="u"/>
    </Controller>
    <Actuator name="u" channel="u" topic="u" min="-10" max="10" safeValue="0" commandTimeout="0.2"/>
  </Node>
  <Node name="idle" kind="service"/>
</System>"""


class Handover:
    """The giver node in this process, the idle node in a child ``ckm-run``; :meth:`hand` hands the PID over."""

    def __init__(self, directory: Path, join_timeout: float = 20.0) -> None:
        settings = private_settings("multipeer")
        self.path = directory / "delegation.xml"
        self.path.write_text(CONFIG.format(group=settings["group"], dport=settings["discovery_port"],
                                           base=settings["base_port"], period=PERIOD))  # fmt: skip
        system = ckmconf.load(self.path)
        assert system.network is not None
        self.transport: Transport = open_transport(system.network, name="giver")
        self.transport.setup()
        self.transport.start()
        self.runtime = NodeRuntime(system.nodes[0], system, self.transport)
        self.runtime.setup()
        self.runtime.start()
        self.taker = subprocess.Popen(
            [sys.executable, "-m", "runtime.cli", str(self.path), "--node", "idle", "--duration", "120",
             "--log-dir", str(directory / "idle")],
            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        self.outputs: list[Sample] = []
        self.transport.subscribe(self.runtime.topic("u"), self.outputs.append)
        self.reference = self.transport.publisher(self.runtime.topic("r"))
        deadline = time.monotonic() + join_timeout
        while time.monotonic() < deadline and not self.transport.peers():
            self._drive(1)
        if not self.transport.peers():
            self.close()
            raise RuntimeError(f"the idle node never joined in {join_timeout:g} s")

    def _drive(self, periods: int) -> None:
        for _ in range(periods):
            self.reference.publish(1.0)
            time.sleep(PERIOD)

    def hand(self, before: int = 25, after: int = 50) -> dict[str, Any]:
        """Run ``before`` periods, hand the PID to ``idle``, run ``after``; the outputs heard around it."""
        self._drive(before)
        delegation = self.runtime.delegation
        if delegation is None or not delegation.give("pid", "idle"):
            raise RuntimeError("the giver refused to hand the controller over")
        handed = len(self.outputs)
        self._drive(after)
        window = self.outputs[max(0, handed - 20) : handed + 40]
        return {"handed": handed, "stamps": [s.stamp for s in window],
                "sources": [s.source == self.transport.guid for s in window]}  # fmt: skip

    def close(self) -> None:
        """Stop the taker (bounded waits), then the giver."""
        self.taker.terminate()
        try:
            self.taker.wait(20)
        except subprocess.TimeoutExpired:
            self.taker.kill()
            self.taker.wait(5)
        self.runtime.stop()
        self.transport.stop()

    def __enter__(self) -> Handover:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        self.close()


def measure(window: dict[str, Any]) -> dict[str, Any]:
    """One handover's figures: gaps in periods, giver outputs after the taker's first (``overlap``)."""
    stamps, by_giver = window["stamps"], window["sources"]
    gaps = [(b - a) / PERIOD for a, b in itertools.pairwise(stamps)]
    first_taker = next((i for i, giver in enumerate(by_giver) if not giver), None)
    overlap = 0 if first_taker is None else sum(by_giver[first_taker:])
    return {"max_gap_periods": round(max(gaps), 3) if gaps else None,
            "min_gap_periods": round(min(gaps), 3) if gaps else None,
            "overlap": overlap, "taker_published": first_taker is not None}  # fmt: skip


def run(argv: list[str] | None = None) -> dict[str, Any]:
    """``ckm-bench delegation [--runs N]``: N handovers, each on a fresh pair of nodes."""
    parser = argparse.ArgumentParser(prog="ckm-bench delegation")
    parser.add_argument("--runs", type=int, default=5, help="handovers (default 5)")
    options = parser.parse_args(argv or [])
    if options.runs < 1:
        parser.error("--runs must be at least 1")
    handovers = []
    for _ in range(options.runs):
        with tempfile.TemporaryDirectory(prefix="ckm-delegation-") as directory, Handover(Path(directory)) as pair:
            handovers.append(measure(pair.hand()))
    gaps = [h["max_gap_periods"] for h in handovers if h["max_gap_periods"] is not None]
    lows = [h["min_gap_periods"] for h in handovers if h["min_gap_periods"] is not None]
    return {"period_s": PERIOD, "runs": options.runs, "handovers": handovers,
            "max_gap_periods": max(gaps) if gaps else None, "min_gap_periods": min(lows) if lows else None,
            "overlap": sum(h["overlap"] for h in handovers),
            "taker_published": all(h["taker_published"] for h in handovers)}  # fmt: skip


def describe(result: dict[str, Any]) -> list[tuple[str, str]]:
    """The rows of ``ckm-bench delegation``'s table."""
    return [
        ("handovers", f"{result['runs']} at a {result['period_s'] * 1000:g} ms period"),
        ("largest output gap around a handover", f"{result['max_gap_periods']} periods (claim: < 2)"),
        ("smallest output gap around a handover", f"{result['min_gap_periods']} periods (claim: > 0)"),
        ("giver outputs after the taker's first", str(result["overlap"])),
        ("the taker published every time", "yes" if result["taker_published"] else "NO"),
    ]
