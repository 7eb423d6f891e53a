"""ckmconf: load, validate and write CKM configurations (thesis §3.1.5.1–3.1.5.2, schemas/ckm.xsd).

``load(path)`` parses safely, validates against ``schemas/`` and checks cross-references,
returning frozen records; ``dump(record)`` writes them back as stable, diff-friendly XML.
"""

from .errors import ConfigError, ConfigErrors, Loc
from .loader import LoadResult, load, load_bytes, read_document
from .source import Limits
from .writer import dump, dumps

__all__ = [
    "ConfigError",
    "ConfigErrors",
    "Limits",
    "LoadResult",
    "Loc",
    "dump",
    "dumps",
    "load",
    "load_bytes",
    "read_document",
]
