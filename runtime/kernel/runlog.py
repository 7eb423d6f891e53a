"""What a run writes into its run directory, as it happens (issue G: a SIGKILL loses at most the last moment).

Events (node events, network lost/found/linked/unlinked) are appended to ``events.jsonl`` and
flushed one line at a time; the statistics are rewritten atomically (temporary file, then
rename) every few seconds and at the stop. Several ``ckm-run --node N`` processes may share one
run directory: the first to claim it writes ``stats.json`` / ``events.jsonl``, each other one
``stats-N.json`` / ``events-N.jsonl`` (decision D64), so none overwrites another's files.
"""

from __future__ import annotations

import json
import logging
import os
import threading
from pathlib import Path
from typing import IO, Any

LOG = logging.getLogger("ckm.run")


def _claim(path: Path) -> bool:
    """Create ``path`` if nobody has: True when this process now owns it."""
    try:
        fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError:
        return False
    os.close(fd)
    return True


class RunLog:
    """The events and statistics files of one process in a run directory."""

    def __init__(self, run_dir: Path, *, shared_as: str | None = None) -> None:
        """``shared_as``: None when this process alone writes the directory (its files are
        replaced); a name (the node's) when other processes may write it too."""
        run_dir.mkdir(parents=True, exist_ok=True)
        self.run_dir = run_dir
        suffix = ""
        if shared_as is not None and not _claim(run_dir / "stats.json"):
            suffix = f"-{shared_as}"
            if not _claim(run_dir / f"stats{suffix}.json"):
                suffix = f"-{shared_as}-{os.getpid()}"
        self.stats_path = run_dir / f"stats{suffix}.json"
        self.events_path = run_dir / f"events{suffix}.jsonl"
        self._lock = threading.Lock()
        self._events: IO[str] | None = self.events_path.open("w", encoding="utf-8")

    def event(self, event: dict[str, Any]) -> None:
        """Append one event and flush it: it survives the process being killed right after."""
        line = json.dumps(event, default=str) + "\n"
        with self._lock:
            if self._events is None:
                return
            try:
                self._events.write(line)
                self._events.flush()
            except (OSError, ValueError):
                LOG.exception("cannot write the event to %s", self.events_path)

    def statistics(self, summary: dict[str, Any]) -> None:
        """Replace the statistics file atomically: a reader never sees half of it."""
        scratch = self.stats_path.with_name(f".{self.stats_path.name}.{os.getpid()}.tmp")
        scratch.write_text(json.dumps(summary, indent=2, default=str), encoding="utf-8")
        os.replace(scratch, self.stats_path)

    def close(self) -> None:
        """Close the event file; later events are dropped."""
        with self._lock:
            if self._events is not None:
                self._events.close()
                self._events = None
