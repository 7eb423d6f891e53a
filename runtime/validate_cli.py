"""ckm-validate: the schema-and-references check of ``ckmconf.cli``, then ``verify`` (issue G).

By default each file that loads cleanly is also verified against the registered kinds' manifests
(kinds, Params, message types, channel sizes, what the runtime could not run), so a file that
validates is one ``ckm-run`` can build. ``--schema-only`` gives the bare check of ``ckmconf``.
Output and exit codes are DESIGN.md's contract: one ``FILE:LINE:COL: XPATH: message`` line per
problem (or ``--json``), exit 0 when there is none, 1 otherwise, never a traceback.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from ckmconf import cli
from ckmconf.errors import ConfigError
from ckmconf.model import System

from .verification.verify import verify_safely


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``ckm-validate`` on the configuration files of ``argv`` (schemas/ckm.xsd ``System``, §3.1.5.2).

    Returns:
        The exit code: 0 when no file has a problem, 1 otherwise.
    """
    parser = cli.parser()
    parser.description = (
        "Validate CKM configuration files against the XSD model, check their cross-references, "
        "and verify every kind, Param and message type against the registered plugins."
    )
    parser.add_argument(
        "--schema-only",
        action="store_true",
        help="only the schema and cross-reference check: do not verify kinds, Params and message types",
    )
    args = parser.parse_args(argv)
    return cli.run(args, None if args.schema_only else _verify)


def _verify(system: System) -> list[ConfigError]:
    return verify_safely(system)


if __name__ == "__main__":
    sys.exit(main())
