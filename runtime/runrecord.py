"""What a run leaves behind: its exit code and its record in the run directory (§3.1.5, issue G).

The host (:class:`runtime.host.Host`) writes it for every way of running a node: ``ckm-run``
(:mod:`runtime.cli`) rewrites the statistics every few seconds and at the stop through its
:class:`~runtime.kernel.runlog.RunLog`; the configuration agent (:mod:`runtime.distribution`)
writes a pushed node's ``stats.json`` and ``events.jsonl`` in one go when it retires it. The
exit codes are those of ``docs/exit-codes.md``.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import Any

from ckmconf.model import System

from .kernel.node import NodeRuntime
from .kernel.runlog import RunLog

LOG = logging.getLogger("ckm.run")

EXIT_CONFIG = 1  # the configuration was refused (load, verify, build)
EXIT_NETWORK = 4  # the network could not be joined
EXIT_FAILED = 5  # a partition or a node task failed while running
EXIT_AGENTS = 6  # a plan's agent did not end in its success final


def summary(
    config: Path, system: System, runtimes: list[NodeRuntime], started: float, extra: dict[str, Any]
) -> dict[str, Any]:
    """The statistics of a run: each node's, each partition supervisor's, and ``extra``.

    Args:
        config: the configuration file the run was started with.
        system: the loaded system.
        runtimes: the nodes that ran in this process.
        started: when the run started (``time.time()``).
        extra: host-specific fields (a partition's memory, the agent's name and bundle hash).
    """
    record = {
        "config": str(config),
        "system": system.name,
        "started": started,
        "stopped": time.time(),
        **extra,
        "nodes": {r.node.name: r.statistics() for r in runtimes},
    }
    partitions = {r.node.name: r.partitions.statistics() for r in runtimes if r.partitions is not None}
    if partitions:
        record["partitions"] = partitions
    return record


def keep_statistics(
    run_log: RunLog, config: Path, system: System, runtimes: list[NodeRuntime], started: float, extra: dict[str, Any]
) -> None:
    """Rewrite the run's statistics file now; a failure is logged, never raised (the run goes on)."""
    try:
        run_log.statistics(summary(config, system, runtimes, started, extra))
    except Exception:
        LOG.exception("cannot write the statistics to %s", run_log.stats_path)


def write_run(
    run_dir: Path, config: Path, system: System, runtimes: list[NodeRuntime], started: float, extra: dict[str, Any]
) -> None:
    """stats.json and events.jsonl of a finished run in one go (the distribution agent's pushed nodes)."""
    record = summary(config, system, runtimes, started, extra)
    (run_dir / "stats.json").write_text(json.dumps(record, indent=2, default=str))
    with (run_dir / "events.jsonl").open("w") as events:
        for runtime in runtimes:
            for event in runtime.events:
                events.write(json.dumps(event, default=str) + "\n")
