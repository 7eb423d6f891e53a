"""D212: the use case's Navigation has no goal until a behavior sets one. Its service's ``goal``
default, forwarded to the plugin at start as the Smart Resource runtime does, leaves the robot
standing; it used to be HomeArea, which drove the Turtlebot to the area's centre while NAV_COOP still
waited for the Nao's signal (on the lab, into the drop table's corner, where it stayed)."""

from __future__ import annotations

from ckmconf.loader import load
from plugins.navigation.amcl import AmclNavigation
from runtime.resources.api import typed_default
from tests.conftest import CONFIGS


def test_the_lab_navigation_starts_without_a_goal() -> None:
    system = load(CONFIGS / "usecase" / "lab.xml")
    resource = system.resource("Navigation")
    assert resource is not None
    service = next(s for s in resource.services if s.name == "AMCL")
    defaults = {p.name: typed_default(p) for p in service.parameters if p.default is not None}
    assert defaults == {"goal": ""}
    record = next(p for p in resource.plugins if p.kind == "amcl-navigation")
    navigation = AmclNavigation(record)
    navigation.setup()
    navigation.apply_service_parameters(defaults)  # what the runtime forwards at start
    assert navigation.goal is None and navigation.goal_text == ""
    navigation.apply_service_parameters({"goal": "HomeArea"})  # a behavior's goal still works
    assert navigation.goal is not None and navigation.goal_text == "HomeArea"
