"""``ckm-bag check RUN_DIR…``: a run's rosbag2 bags read back by independent readers (issue L point 2, §4.4.1).

Every bag of each run directory (``RUN_DIR/bag`` of ``ckm-run --record``, ``bag-NODE`` of
``--node`` runs, or a bag directory given directly) is checked by :mod:`runtime.ros.check`: rosbag2
format 9 and ``cdr`` in ``metadata.yaml``; MCAP files with the ``mcap`` reader and the
``mcap-ros2-support`` decoder (profile ``ros2``, ``ros2msg`` schemas), sqlite3 files with
``rosbags``' reader; every message decoded and counted against ``metadata.yaml``. One line per bag
and per topic, or ``--json``. Exit 0 when every bag passes, 1 when one has a problem (each printed
on stderr), 2 when a run directory has no bag.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from .check import BagCheck, check_run


def _print(result: BagCheck) -> None:
    verdict = "ok" if result.ok else f"{len(result.problems)} problem(s)"
    print(
        f"{result.path}: {result.storage}, rosbag2 version {result.version}, {sum(result.decoded.values())} "
        f"messages decoded by {' and '.join(result.readers) or 'no reader'} on {len(result.topics)} topics: {verdict}"
    )
    for topic, ros_type in sorted(result.topics.items()):
        print(f"  {topic} [{ros_type}]: {result.decoded[topic]}/{result.announced[topic]} decoded")


def main(argv: Sequence[str] | None = None) -> int:
    """``ckm-bag check RUN_DIR…`` (see the module docstring); returns the exit code."""
    parser = argparse.ArgumentParser(prog="ckm-bag", description="Check the rosbag2 bags of CKM runs.")
    commands = parser.add_subparsers(dest="command", required=True)
    check = commands.add_parser(
        "check",
        help="read every bag of the runs back with mcap + mcap-ros2-support (MCAP) and rosbags (sqlite3)",
    )
    check.add_argument("runs", nargs="+", type=Path, metavar="RUN_DIR", help="a run directory or a bag directory")
    check.add_argument("--json", action="store_true", help="one JSON object per bag")
    args = parser.parse_args(argv)
    status = 0
    for run in args.runs:
        try:
            results = check_run(run)
        except FileNotFoundError as error:
            print(f"ckm-bag: {error}", file=sys.stderr)
            status = max(status, 2)
            continue
        for result in results:
            if args.json:
                print(json.dumps(result.to_dict()))
            else:
                _print(result)
            for problem in result.problems:
                print(problem, file=sys.stderr)
            if not result.ok:
                status = max(status, 1)
    return status


if __name__ == "__main__":
    sys.exit(main())
