"""The ``<Environment>`` of a file a plugin's Param names (thesis §6.1: the map model's source).

Navigation, the shared map, the pan-tilt tracker and the fusion all read the environment file
their ``environment`` Param names at set-up; this is the one way they do it, with one message.
"""

from __future__ import annotations

from pathlib import Path

from ckmconf import ConfigError, ConfigErrors, read_document
from ckmconf.model import Environment


def environment_of(path: str | Path, owner: str) -> Environment:
    """The ``<Environment>`` of the file ``path`` (read safely by ckmconf).

    Raises:
        ValueError: ``OWNER: cannot use environment file: FILE:LINE:COL: …`` for a missing,
            unreadable or invalid file, or ``… has no Environment``.
    """
    try:
        document = read_document(path)
    except ConfigError as exc:
        raise ValueError(f"{owner}: cannot use environment file: {exc}") from None
    except ConfigErrors as exc:
        raise ValueError(f"{owner}: cannot use environment file: {exc.errors[0]}") from None
    if document.environment is None:
        raise ValueError(f"{owner}: environment file {path} has no Environment")
    return document.environment
