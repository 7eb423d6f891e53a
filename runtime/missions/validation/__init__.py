"""Off-line mission validation (thesis §5.4, §7.5.1): static checks of the HFSM and SRFlowGen.

``check_mission`` finds design errors in a mission graph and in what its behaviors ask of the
Smart Resources; ``srflowgen`` traces every variable a behavior reads back to the services and
sensors producing it and bounds the probability its quality requirements hold (eq. 5.7).
"""

from .check import top_missions
from .findings import Finding
from .srflowgen import FlowReport, StateFlow, VariableFlow, srflowgen
from .static import check_mission

__all__ = ["Finding", "FlowReport", "StateFlow", "VariableFlow", "check_mission", "srflowgen", "top_missions"]
