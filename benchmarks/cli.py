"""ckm-bench NAME [--json]: run a benchmark, print a table; with --json the last line is one JSON object."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from typing import Any

from rich.console import Console
from rich.table import Table

from . import config, jitter, netbench, rates

BENCHMARKS: dict[str, tuple[Callable[[], dict[str, Any]], Callable[[dict[str, Any]], list[tuple[str, str]]]]] = {
    "config": (config.run, config.describe),
    "pubsub": (netbench.run_pubsub, netbench.describe_pubsub),
    "discovery": (netbench.run_discovery, netbench.describe_discovery),
    "jitter": (jitter.run, jitter.describe),
    "rates": (rates.run, rates.describe),
}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ckm-bench", description="Run a CKM benchmark.")
    parser.add_argument("name", choices=sorted(BENCHMARKS), help="which benchmark")
    parser.add_argument("--json", action="store_true", help="end with one line of JSON")
    args = parser.parse_args(argv)
    run, describe = BENCHMARKS[args.name]
    result = run()
    table = Table(title=f"ckm-bench {args.name}")
    table.add_column("measure")
    table.add_column("value", justify="right")
    for label, value in describe(result):
        table.add_row(label, value)
    Console(width=100).print(table)
    if args.json:
        print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
