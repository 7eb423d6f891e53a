"""The use case's RGBDCamera cut down to some of its profiles (§7.4.1, Table 7.3), and a Smart Processing
Topology with each of them selected: what the RGB and the depth pipeline tests run."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ckmconf.loader import load
from ckmconf.model.resources import SmartResource
from runtime.resources.spt import Topology


def camera_with(config: Path, profiles: tuple[str, ...]) -> SmartResource:
    """``config``'s RGBDCamera with only ``profiles`` and the plugins they use."""
    camera = load(config).resource("RGBDCamera")
    assert camera is not None
    kept = tuple(p for p in camera.profiles if p.name in profiles)
    used = {name for p in kept for name in p.root.plugins()}
    return dataclasses.replace(camera, plugins=tuple(p for p in camera.plugins if p.name in used), profiles=kept)


@contextmanager
def every_profile(camera: SmartResource, profiles: tuple[str, ...]) -> Iterator[Topology]:
    """``camera``'s topology set up with each of ``profiles`` selected as its own output; stopped at the end."""
    spt = Topology(camera)
    spt.setup()
    spt.select_all({name: name for name in profiles})
    try:
        yield spt
    finally:
        spt.stop()
