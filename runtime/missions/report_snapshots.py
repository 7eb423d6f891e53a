"""The camera snapshots of the HTML run report: what each robot saw at the moments of Fig. 7.22 / 7.24 (§7.5).

Fig. 7.22 shows one robot's individual mission as a sequence of frames (navigating to the goal
area, recognising the object, grasping it, placing it); Fig. 7.24 the steps a second robot adds
(its camera fixed on the object, the first one spotting it with its help). The report takes the
run's :class:`.report_bag.Moment` s — each agent entering and ending one of the snapshot states, the
states on its mission's success route (:func:`.report_topics.key_states`) — and shows, per agent,
the frame of its own cameras nearest each moment (:func:`agent_cameras`), with the state, the run
time and the frame's distance from the moment under it. A frame further than
:data:`MAX_FRAME_GAP` from its moment is not shown as if it were of it.

Frames are embedded in the page: a ``CompressedImage`` (``ckm-run --record CAMERA@HZ:jpeg``, D197)
as its JPEG/PNG bytes, a raw ``Image`` as a reduced PNG (:func:`.report_figures.image_png`).
"""

from __future__ import annotations

import base64
import io
from collections.abc import Sequence
from html import escape

import numpy as np
from PIL import Image as PilImage

from .report_bag import BagData, Frame, Moment, ReportTopics, compressed_picture, image_pixels
from .report_figures import image_png

MAX_MOMENTS = 40
"""Most moments shown per agent (a run that retries enters the same states many times)."""
MAX_FRAME_GAP = 5.0
"""Seconds: a frame further than this from a moment is not taken as what the camera saw then."""
PER_ROW = 4
"""Snapshots per table row."""
HOW_TO_RECORD = "record the cameras sparsely: ckm-run --record '…,{camera}@0.5:jpeg' (D197)"
"""How to get camera frames into the bag, for one of the camera topics."""


def _note(text: str, kind: str = "note") -> str:
    return f'<p class="{kind}">{escape(text)}</p>'


def agent_cameras(agent: str, cameras: Sequence[str]) -> list[str]:
    """The camera topics of ``agent``: those with the agent's name as a part of the topic name
    (``/robot1/camera_raw`` for ``robot1``, ``/robot2/head/image`` for ``robot2``); every camera when
    no topic names it (one robot, or cameras named otherwise)."""
    own = [c for c in cameras if agent.lower() in c.lower().strip("/").split("/")]
    return own or list(cameras)


def picture_tag(frame: Frame) -> str:
    """The frame as an embedded ``<img>``: compressed bytes as they are (a 16-bit PNG scaled to
    8 bits, which browsers would show dark), a raw image as a reduced PNG.

    Raises:
        ValueError: the payload is no picture the report can show.
    """
    alt = escape(frame.moment.label)
    picture = compressed_picture(frame.payload)
    if picture is None:
        data, kind = image_png(image_pixels(frame.payload)), "image/png"
    else:
        kind, data = picture
        if kind == "image/png" and "16" in str(frame.payload.get("format", "")):
            with PilImage.open(io.BytesIO(data)) as opened:
                data = image_png(np.asarray(opened))
    return f'<img alt="{alt}" src="data:{kind};base64,{base64.b64encode(data).decode("ascii")}">'


def _cell(frame: Frame | None, moment: Moment, camera: str, several: bool) -> str:
    """One snapshot: the picture, then the state, how the moment came and its run time, and how
    far the frame was from it (or why there is no picture)."""
    caption = f"<b>{escape(moment.state)}</b> {escape(moment.edge)} at {moment.run_time:.1f} s"
    where = f"{escape(camera)}, " if several else ""
    if frame is None:
        return f'<span class="note">no frame</span><br>{caption}<br><small>{where}nothing recorded</small>'
    if abs(frame.offset) > MAX_FRAME_GAP:
        gap = f"the nearest frame is {frame.offset:+.1f} s from it (more than {MAX_FRAME_GAP:g} s)"
        return f'<span class="note">no frame</span><br>{caption}<br><small>{where}{gap}</small>'
    try:
        picture = picture_tag(frame)
    except ValueError as error:
        return f'<span class="error">frame not shown: {escape(str(error))}</span><br>{caption}'
    return f"{picture}<br>{caption}<br><small>{where}frame {frame.offset:+.2f} s from it</small>"


def snapshots_section(data: BagData, topics: ReportTopics, moments: Sequence[Moment], states: Sequence[str]) -> str:
    """Per agent, the frame of its cameras nearest each of its ``moments`` (entering or ending ``states``)."""
    if not moments:
        entered = ", ".join(states) or "a state"
        return _note(f"No moment to show: no agent entered {entered} (or the recordings have no wall time).")
    if not topics.cameras:
        return _note("No camera frames: no camera topic (none known from the configuration; name one with "
                     "--camera-topic).")  # fmt: skip
    wanted = topics.camera_topics()
    present = [t for t in wanted if t in data.topics]
    if not data.bags or not present:
        where = "no bag in the run" if not data.bags else "none of them in the bag"
        how = HOW_TO_RECORD.format(camera=topics.cameras[0])
        return _note(f"No camera frames: topic {' / '.join(topics.cameras)}: {where}; {how}.")
    cameras = [c for c in present if any(f.topic == c for f in data.frames)]
    if not cameras:
        counts = ", ".join(f"{t} {data.stored.get(t, 0)} message(s)" for t in present)
        return _note(f"No camera frames: in the bag {counts}, none read.")
    frames = {(f.topic, f.moment): f for f in data.frames}
    out = []
    for agent in dict.fromkeys(m.agent for m in moments):
        mine = [m for m in moments if m.agent == agent]
        own = agent_cameras(agent, cameras)
        cells = [_cell(frames.get((c, m)), m, c, len(own) > 1) for m in mine[:MAX_MOMENTS] for c in own]
        rows = ["".join(f"<td>{c}</td>" for c in cells[i : i + PER_ROW]) for i in range(0, len(cells), PER_ROW)]
        out.append(f"<h3>{escape(agent)}: {escape(', '.join(own))}</h3>")
        out.append(
            f'<table class="snapshots agent-{escape(agent)}">' + "".join(f"<tr>{r}</tr>" for r in rows) + "</table>"
        )
        if len(mine) > MAX_MOMENTS:
            out.append(
                _note(f"{len(mine) - MAX_MOMENTS} later moment(s) of {agent} not shown (the first {MAX_MOMENTS} are).")
            )
    return "".join(out)
