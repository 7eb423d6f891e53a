"""ckm-bench NAME [--json]: run a benchmark, print a table; with --json the last line is one JSON object."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from typing import Any

from rich.console import Console
from rich.table import Table

from . import adaptation, config, jitter, netbench, rates

Runner = Callable[[], dict[str, Any]]
Describer = Callable[[dict[str, Any]], list[tuple[str, str]]]
BENCHMARKS: dict[str, tuple[Runner, Describer]] = {
    "adaptation": (adaptation.run, adaptation.describe),
    "config": (config.run, config.describe),
    "pubsub": (netbench.run_pubsub, netbench.describe_pubsub),
    "discovery": (netbench.run_discovery, netbench.describe_discovery),
    "jitter": (jitter.run, jitter.describe),
    "rates": (rates.run, rates.describe),
}
TAKES_OPTIONS = {"adaptation"}  # ckm-bench adaptation --help lists them


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ckm-bench", description="Run a CKM benchmark.")
    parser.add_argument("name", choices=sorted(BENCHMARKS), help="which benchmark")
    parser.add_argument("--json", action="store_true", help="end with one line of JSON")
    args, extra = parser.parse_known_args(argv)
    run, describe = BENCHMARKS[args.name]
    if extra and args.name not in TAKES_OPTIONS:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    result = adaptation.run(extra) if args.name == "adaptation" else run()
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
