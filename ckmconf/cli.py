"""ckm-validate: check configuration files (§3.1.5.2); one line per problem, FILE:LINE:COL: XPATH: message.

This module is the schema-and-references check (``ckmconf`` alone). The installed ``ckm-validate``
(``runtime.validate_cli``) adds the verification of kinds, Params and message types through
``run(…, check=…)``; ``python -m ckmconf.cli`` is the bare check, as ``ckm-validate --schema-only``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from .errors import ConfigError, errors_to_json
from .loader import LoadResult, load
from .model import System
from .source import Limits

Check = Callable[[System], list[ConfigError]]
"""A further check of a loaded, valid system (``runtime``'s verify), run after loading."""


def parser() -> argparse.ArgumentParser:
    """The ckm-validate options (callers may add their own before parsing)."""
    parser = argparse.ArgumentParser(
        prog="ckm-validate",
        description="Validate CKM configuration files against the XSD model and check their cross-references.",
    )
    parser.add_argument("files", nargs="+", metavar="FILE", help="System or Part files")
    parser.add_argument("--json", action="store_true", help="print the problems as a JSON list")
    parser.add_argument("--summary", action="store_true", help="print what each valid system holds")
    parser.add_argument(
        "--max-bytes", type=int, default=Limits().max_bytes, metavar="N", help="refuse files larger than N bytes"
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: parse ``argv`` and :func:`run`; exit status 0 when every file is valid."""
    return run(parser().parse_args(argv))


def run(args: argparse.Namespace, check: Check | None = None) -> int:
    """Load every file of ``args``, apply ``check`` to each system that loaded cleanly, report.

    Returns:
        0 when no file has a problem, else 1 (DESIGN.md's ckm-validate contract).
    """
    limits = Limits(max_bytes=args.max_bytes)
    errors: list[ConfigError] = []
    results: list[tuple[str, LoadResult]] = []
    checked: set[ConfigError] = set()
    for path in args.files:
        try:
            result = load(path, strict=False, limits=limits)
        except RecursionError:  # pathological nesting that slipped past the parser limits
            result = LoadResult(None, [ConfigError(path, 1, 1, "/", "elements are nested too deeply")])
        if check is not None and result.system is not None and not result.errors:
            # A Part included by several files given is checked with each: report its problems once.
            found = [e for e in check(result.system) if e not in checked]
            checked.update(found)
            result = LoadResult(result.system, found, result.files)
        errors.extend(result.errors)
        results.append((path, result))
    if args.json:
        print(errors_to_json(errors))
    else:
        for error in errors:
            print(error)
        if args.summary:
            for path, result in results:
                if result.system is not None and not result.errors:
                    _print_summary(path, result.system, len(result.files))
    return 1 if errors else 0


def _print_summary(path: str, system: System, files: int) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"{path}: system {system.name!r} ({files} file{'s' if files != 1 else ''}), valid")
    table.add_column("kind")
    table.add_column("count", justify="right")
    table.add_column("names")
    rows = [
        ("nodes", [n.name for n in system.nodes]),
        ("sensors", [f"{n.name}.{s.name}" for n in system.nodes for s in n.sensors]),
        ("controllers", [f"{n.name}.{c.name}" for n in system.nodes for c in n.controllers]),
        ("actuators", [f"{n.name}.{a.name}" for n in system.nodes for a in n.actuators]),
        ("smart resources", [r.name for r in system.resources]),
        ("services", [f"{r.name}.{s.name}" for r in system.resources for s in r.services]),
        ("behaviors", [b.name for b in system.behaviors]),
        ("missions", [f"{m.name} ({len(m.states)} states)" for m in system.missions]),
        ("plans", [f"{p.name}: " + ", ".join(f"{a.name}→{a.mission}" for a in p.agents) for p in system.plans]),
        ("environment objects", [o.name for o in system.environment.objects] if system.environment else []),
    ]
    for kind, names in rows:
        shown = ", ".join(names[:8]) + (f", … (+{len(names) - 8})" if len(names) > 8 else "")
        table.add_row(kind, str(len(names)), shown)
    Console(width=160).print(table)


if __name__ == "__main__":
    sys.exit(main())
