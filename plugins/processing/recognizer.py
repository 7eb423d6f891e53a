"""``plugin.orb-recognition``: ORB keypoints and model matching in one plugin.

For configurations that want recognition as one step of a profile (the SPT examples); the use
case splits it into ``orb-keypoints`` → ``keypoint-matching`` so that the keypoints could feed
other consumers. Its Params are the union of the two plugins' and are checked by them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model.resources import Plugin
from runtime.resources.spt import Context, ProcessingPlugin
from runtime.verification.manifest import ARRAY, MAPPING, Ports, as_params

from .recognition import KeypointMatching, OrbKeypoints


def _part(record: Plugin, cls: type[ProcessingPlugin]) -> Plugin:
    return dataclasses.replace(record, params=tuple(p for p in record.params if p.name in cls.PARAMS))


class OrbRecognition(ProcessingPlugin):
    """ORB keypoints and texture matching in one step: an image in, the matching result out (see
    :class:`KeypointMatching` for its fields)."""

    PORTS = Ports(inputs={"*": ARRAY}, outputs={"*": MAPPING})  # an image in, objects + reliability out
    PROVIDES = "object-detection"  # docs/interfaces.md
    POSITIONS = "image"  # x, y: shares of the frame (plugins.behaviors.upstream)
    WRITES = KeypointMatching.WRITES
    PARAMS: ClassVar[Mapping[str, Any]] = as_params(OrbKeypoints.PARAMS) | KeypointMatching.PARAMS

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)  # rejects a Param neither part knows
        self.keypoints = OrbKeypoints(_part(record, OrbKeypoints))
        self.matching = KeypointMatching(_part(record, KeypointMatching))

    def setup(self) -> None:
        """Set up the keypoint and the matching steps."""
        self.keypoints.setup()
        self.matching.setup()

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The matching result of the image ``data``."""
        return self.matching.process(self.keypoints.process(data, context), context)

    def stop(self) -> None:
        """Stop both steps."""
        self.matching.stop()
        self.keypoints.stop()
