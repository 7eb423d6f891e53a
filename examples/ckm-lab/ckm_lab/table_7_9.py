"""The thesis' Table 7.9 (§7.5.2, p. 132) as a reference table of the run report (D272).

Table 7.9 characterises the cooperative mission of Fig. 7.13 by behavior: execution time,
contribution to the mission (a fraction, though the header says %) and average performance. Its
rows group states differently from the lab's missions (configs/usecase/missions.xml): NAVIGATION
has two visits, going to the workbench and coming back home, which are the ``Navigation``
sub-mission and the ``NAV``/``WAIT`` states of ``ObjectPlace``; APPR-PICK and PLACE-BACK join two
of the lab's states; SPOT_TRACK and SPOT_FIX are the Nao's OBJ_TRACK and OBJ_FIX. Each row
therefore names, per visit, the ``fnmatch`` patterns of the leaf rows' labels it stands for
(:class:`runtime.missions.report_references.ReferenceRow`). The package registers it in the
entry-point group ``ckm.report_references``.
"""

from __future__ import annotations

from runtime.missions.report_references import ReferenceRow, ReferenceTable

ROWS: tuple[ReferenceRow, ...] = (
    ReferenceRow(
        "NAVIGATION", (56.676, 52.856), (0.29, 0.27), 0.89, (("Navigation/*",), ("ObjectPlace/NAV", "ObjectPlace/WAIT"))
    ),
    ReferenceRow("SPOT", (18.651,), (0.096,), 0.74, (("*SPOT",),)),
    ReferenceRow("APPR-PICK", (58.713,), (0.30,), 0.93, (("*APPR", "*PICK"),)),
    ReferenceRow("PLACE-BACK", (26.121,), (0.13,), 0.95, (("*PLACE", "*BACK"),)),
    ReferenceRow("SPOT_TRACK", (23.57,), (0.24,), 1.0, (("*OBJ_TRACK",),)),
    ReferenceRow("SPOT_FIX", (75.327,), (0.76,), 0.62, (("*OBJ_FIX",),)),
)
"""Table 7.9 of the thesis (p. 132): Agent 1's rows, then Agent 2's."""

TABLE_7_9 = ReferenceTable("thesis Table 7.9 (§7.5.2, p. 132)", ROWS)
"""The table the report shows beside a lab run's rows."""
