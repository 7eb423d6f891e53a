"""Records of the Smart Resource layer (schemas/resources.xsd, thesis ch. 4)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..binding import Record, attr, child, children
from .params import Param


@dataclass(frozen=True, kw_only=True)
class Plugin(Record):
    """<Plugin>: an SPT processing plugin instance."""

    TAG = "Plugin"
    name: str = attr()
    kind: str = attr()
    params: tuple[Param, ...] = children()


@dataclass(frozen=True, kw_only=True)
class Use(Record):
    """<Use>: a plugin in a profile's composition tree; children consume its output."""

    TAG = "Use"
    plugin: str = attr()
    uses: tuple[Use, ...] = children()

    def plugins(self) -> list[str]:
        """Plugins of this subtree, parents first."""
        found = [self.plugin]
        for use in self.uses:
            found.extend(use.plugins())
        return found

    def leaves(self) -> list[str]:
        """Plugin names of the tree's leaves (the profile's final outputs), depth first."""
        if not self.uses:
            return [self.plugin]
        return [leaf for use in self.uses for leaf in use.leaves()]


@dataclass(frozen=True, kw_only=True)
class Profile(Record):
    """<Profile>: an SPT execution profile, one composition of plugins (§3.2.2)."""

    TAG = "Profile"
    name: str = attr()
    output: str | None = attr(default=None)
    description: str | None = attr(default=None)
    root: Use = child()

    def output_plugin(self) -> str:
        """The plugin whose result is the profile's output."""
        return self.output if self.output is not None else self.root.leaves()[0]


@dataclass(frozen=True, kw_only=True)
class DataPort(Record):
    """A named data topic of a service."""

    name: str = attr()
    topic: str = attr()


@dataclass(frozen=True, kw_only=True)
class ServiceInput(DataPort):
    """<Input>: a data topic a service consumes."""

    TAG = "Input"


@dataclass(frozen=True, kw_only=True)
class ServiceOutput(DataPort):
    """<Output>: a data topic a service produces."""

    TAG = "Output"


@dataclass(frozen=True, kw_only=True)
class Parameter(Record):
    """<Parameter>: a configuration parameter of a service."""

    TAG = "Parameter"
    name: str = attr()
    type: Literal["bool", "int", "float", "string", "enum"] = attr()
    default: str | None = attr(default=None)
    min: float | None = attr(default=None)
    max: float | None = attr(default=None)
    values: tuple[str, ...] | None = attr(default=None)
    description: str | None = attr(default=None)


Domain = Literal["temporal", "spatial", "performance"]


@dataclass(frozen=True, kw_only=True)
class QualityMeasure(Record):
    """<QualityMeasure>: a QoS or QoC measure of a service (§4.2.1.1)."""

    TAG = "QualityMeasure"
    name: str = attr()
    kind: Literal["qos", "qoc"] = attr(default="qoc")
    domain: Domain = attr()
    source: str = attr()
    unit: str = attr(default="")
    description: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class CombinedMeasure(Record):
    """<CombinedMeasure>: the sum of independent quality measures, distributed as their convolution (eq. 4.5)."""

    TAG = "CombinedMeasure"
    name: str = attr()
    measures: tuple[str, ...] = attr()
    resolution: float | None = attr(default=None)
    unit: str = attr(default="")
    description: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class Policy(Record):
    """<Policy>: a quality policy, bounds and required probability (eq. 4.2, 4.4)."""

    TAG = "Policy"
    measure: str = attr()
    lower: float | None = attr(default=None)
    upper: float | None = attr(default=None)
    probability: float = attr(default=0.95)
    window: int = attr(default=50)


@dataclass(frozen=True, kw_only=True)
class Scenario(Record):
    """<Scenario>: an SPT profile with the quality policies it must meet (eq. 4.6)."""

    TAG = "Scenario"
    name: str = attr()
    profile: str = attr()
    weight: float = attr(default=1.0)
    policies: tuple[Policy, ...] = children()


TCM_PERIOD = 0.5  # s, the TCM's evaluation period when <TCM period> is absent (resources.xsd says the same)


@dataclass(frozen=True, kw_only=True)
class TCM(Record):
    """<TCM>: Task Configuring Module settings (eq. 4.7-4.10)."""

    TAG = "TCM"
    threshold: float = attr(default=0.5)
    penalty: float = attr(default=0.0)
    penalty_step: float = attr(default=0.1)
    c: float = attr(xml="C", default=1.0)
    period: float = attr(default=TCM_PERIOD)
    learning: Literal["svm", "none"] = attr(default="svm")
    initial: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class Service(Record):
    """<Service>: a Smart Resource service and its API topics (§4.3)."""

    TAG = "Service"
    name: str = attr()
    function: str | None = attr(default=None)
    interface: str | None = attr(default=None)
    rate: float | None = attr(default=None)
    performance: str | None = attr(default=None)
    config_topic: str | None = attr(default=None)
    quality_topic: str | None = attr(default=None)
    alarm_topic: str | None = attr(default=None)
    lazy: bool = attr(default=False)
    inputs: tuple[ServiceInput, ...] = children()
    outputs: tuple[ServiceOutput, ...] = children()
    parameters: tuple[Parameter, ...] = children()
    measures: tuple[QualityMeasure, ...] = children()
    combined: tuple[CombinedMeasure, ...] = children()
    scenarios: tuple[Scenario, ...] = children()
    tcm: TCM | None = child(default=None)

    def combinations(self) -> dict[str, tuple[str, ...]]:
        """Each combined measure's name and the measures it sums (eq. 4.5)."""
        return {c.name: c.measures for c in self.combined}

    def measure_names(self) -> list[str]:
        """Every measure a Policy or a client's requirement may bound: quality, then combined ones."""
        return [m.name for m in self.measures] + [c.name for c in self.combined]


@dataclass(frozen=True, kw_only=True)
class SmartResource(Record):
    """<SmartResource>: a service provider hosted on a node (§4.1)."""

    TAG = "SmartResource"
    name: str = attr()
    node: str = attr()
    kernel: Literal["ckm", "ros"] = attr(default="ckm")
    description: str | None = attr(default=None)
    plugins: tuple[Plugin, ...] = children()
    profiles: tuple[Profile, ...] = children()
    services: tuple[Service, ...] = children()

    def topics_of(self, service: Service) -> dict[str, str]:
        """The service's configuration, quality and alarm topics (standard names when omitted)."""
        base = f"/{self.name}/{service.name}"
        return {
            "config": service.config_topic or f"{base}/config",
            "quality": service.quality_topic or f"{base}/quality",
            "alarms": service.alarm_topic or f"{base}/alarms",
        }
