"""docs/behaviors.md, the behavior library's page, lists every behavior kind the toolkit ships with the
aliases its manifest declares (issue M: users port their systems from the docs alone)."""

from __future__ import annotations

import re
from pathlib import Path

from runtime.registry import Registry
from runtime.verification.interfaces import uses_of

PAGE = Path(__file__).resolve().parents[3] / "docs" / "behaviors.md"


def _rows() -> dict[str, str]:
    """Each table row's first-column kinds (`a`, `b`) → the row's Uses cell."""
    rows: dict[str, str] = {}
    for line in PAGE.read_text(encoding="utf-8").splitlines():
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))]  # an escaped bar stays in its cell
        if len(cells) < 2 or not cells[0].startswith("`"):
            continue
        for kind in re.findall(r"`([a-z-]+)`", cells[0]):
            rows[kind] = cells[1]
    return rows


def test_every_shipped_behavior_kind_has_a_row_naming_its_aliases() -> None:
    registry = Registry(packages=("ckm",))
    rows = _rows()
    missing = [kind for kind in registry.kinds("behavior") if kind not in rows]
    assert missing == [], f"docs/behaviors.md lacks rows for {missing}"
    for kind in registry.kinds("behavior"):
        cls = registry.find("behavior", kind)
        assert cls is not None
        for use in uses_of(cls) or ():
            assert f"`{use.alias}`" in rows[kind], f"{kind}: the page's Uses cell does not name alias {use.alias!r}"
