"""``plugin.threshold``: a grey image turned into a binary mask (the processing-plugin example).

Pixels at or above ``level`` become 255, the others 0 (``invert`` swaps them). The input is any
2-D array (the output of ``plugin.grayscale``, say) and is never modified: it may be shared with
other profiles of the same frame.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from ckmconf.model.resources import Plugin
from runtime.resources.spt import Context, ProcessingPlugin
from runtime.verification.manifest import P, Params


class Threshold(ProcessingPlugin):
    """A binary mask of the pixels at or above a grey level."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("level", 128.0, "Grey level from which a pixel is on.", min=0.0, max=255.0),
        P("invert", False, "Mark the pixels below the level instead."),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)  # converts and checks the Params into self.params

    def process(self, data: Any, context: Context) -> Any:
        """The binary mask of the grey image ``data`` (a Smart Plugin Topology step, §3.2.2); ``data`` is not modified.

        Raises:
            ValueError: ``data`` is not a 2-D array.
        """
        image = np.asarray(data)
        if image.ndim != 2:
            raise ValueError(f"{self.owner} expects a grey (H, W) image, got shape {image.shape}")
        on = image >= self.params["level"]
        if self.params["invert"]:
            on = ~on
        return np.where(on, 255, 0).astype(np.uint8)
