"""The editor's pure-Python model: the schema as forms, allowed children and value checks (no Qt)."""

from .schema import ChildSpec, ElementSpec, SchemaModel
from .values import AttributeSpec, Kind

__all__ = ["AttributeSpec", "ChildSpec", "ElementSpec", "Kind", "SchemaModel"]
