"""ckm-bench NAME [--json] [OPTIONS]: run a benchmark, print a table; with --json the last line is one JSON object.

Each benchmark is a module imported only when named (pybullet or Qt are not loaded for a network
benchmark). A module either takes options (``run(argv)``, listed in ``TAKES_OPTIONS``; its
``--help`` lists them) or none (``run()``); ``describe(result)`` gives the table's rows.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from collections.abc import Callable, Sequence
from typing import Any

from rich.console import Console
from rich.table import Table

Runner = Callable[..., dict[str, Any]]
Describer = Callable[[dict[str, Any]], list[tuple[str, str]]]
# name → (module, run function, describe function)
BENCHMARKS: dict[str, tuple[str, str, str]] = {
    "adaptation": ("benchmarks.adaptation", "run", "describe"),
    "config": ("benchmarks.config", "run", "describe"),
    "delegation": ("benchmarks.delegation", "run", "describe"),
    "pubsub": ("benchmarks.netbench", "run_pubsub", "describe_pubsub"),
    "discovery": ("benchmarks.netbench", "run_discovery", "describe_discovery"),
    "fusion": ("benchmarks.fusion", "run", "describe"),
    "jitter": ("benchmarks.jitter", "run", "describe"),
    "localization": ("benchmarks.localization", "run", "describe"),
    "mission": ("benchmarks.mission", "run", "describe"),
    "rates": ("benchmarks.rates_run", "run_cli", "describe"),
    "soak": ("benchmarks.soak", "run", "describe"),
    "sim": ("benchmarks.sim", "run", "describe"),
    "zoom": ("benchmarks.zoom", "run", "describe"),
}
# These take their own options: ckm-bench NAME --help lists them.
TAKES_OPTIONS = {"adaptation", "delegation", "fusion", "localization", "mission", "rates", "soak", "zoom"}


def resolve(name: str) -> tuple[Runner, Describer]:
    """The run and describe functions of benchmark ``name``."""
    module_name, run_name, describe_name = BENCHMARKS[name]
    module = importlib.import_module(module_name)
    run: Runner = getattr(module, run_name)
    describe: Describer = getattr(module, describe_name)
    return run, describe


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``ckm-bench NAME``: the benchmark, its table, and with ``--json`` one JSON line last.

    Returns:
        The exit code (0; bad arguments exit through argparse).
    """
    parser = argparse.ArgumentParser(prog="ckm-bench", description="Run a CKM benchmark.")
    parser.add_argument("name", choices=sorted(BENCHMARKS), help="which benchmark")
    parser.add_argument("--json", action="store_true", help="end with one line of JSON")
    words = list(sys.argv[1:] if argv is None else argv)
    named = [w for w in words if w in BENCHMARKS]
    if named and named[0] in TAKES_OPTIONS and {"-h", "--help"} & set(words):
        resolve(named[0])[0](["--help"])  # the benchmark's own options (its parser exits)
        return 0
    args, extra = parser.parse_known_args(words)
    if extra and args.name not in TAKES_OPTIONS:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    run, describe = resolve(args.name)
    result = run(extra) if args.name in TAKES_OPTIONS else run()
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
