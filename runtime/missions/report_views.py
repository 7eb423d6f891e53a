"""The sections of the HTML run report drawn from the run's bags (:mod:`.report_bag`): Fig. 7.16 and
Fig. 7.19 (the camera frames of Fig. 7.22 / 7.24: :mod:`.report_snapshots`); each says what it lacks
instead of failing.

Bag times are seconds since the epoch; the recordings' run time is ``epoch − origin`` where the
origin is the recordings' wall anchor (:func:`.html_report._origin`), so every plot shares the time
axis of Table 7.9 and Fig. 7.23.
"""

from __future__ import annotations

import base64
import math
from bisect import bisect_left
from collections.abc import Callable, Collection, Sequence
from html import escape
from pathlib import Path

from ckmconf.model import System
from ckmconf.model.environment import ZoomMap

from .report import Report
from .report_bag import BagData, ReportTopics, Sighting
from .report_figures import Approach, map_png, reliability_png

ZoomArea = tuple[float, float, float, float, float]  # run time, centre x, y, width, depth
POSE_GAP = 1.0
"""Longest time (s) between a recognition and the robot pose it is measured from."""


def png_tag(data: bytes, alt: str) -> str:
    """An ``<img>`` embedding PNG ``data`` inline (the report is one self-contained file)."""
    return f'<img alt="{escape(alt)}" src="data:image/png;base64,{base64.b64encode(data).decode("ascii")}">'


def note(text: str, kind: str = "note") -> str:
    """A ``<p class=kind>`` paragraph (``note`` or ``error``) saying what a section lacks."""
    return f'<p class="{kind}">{escape(text)}</p>'


def _missing(what: str, topics: Sequence[str], data: BagData, option: str = "") -> str:
    """Why ``what`` is not shown: no topic for it (the configuration has none, the command line named
    none with ``option``), no bag, none of ``topics`` in it, or there without (usable) messages."""
    topics = [t for t in topics if t]
    if not topics:
        given = f"; name one with {option}" if option else ""
        return note(f"No {what}: no topic to read it from (none known from the configuration{given}).")
    if not data.bags:
        return note(f"No {what}: topic {' / '.join(topics)}: no bag in the run.")
    there = [t for t in topics if t in data.topics]
    if not there:
        return note(f"No {what}: topic {' / '.join(topics)} not in the bag{'s' if len(data.bags) > 1 else ''}.")
    counts = ", ".join(f"{t} {data.stored.get(t, 0)} message(s)" for t in there)
    return note(f"No {what}: in the bag {counts}, none usable ({' / '.join(topics)} looked for).")


def map_section(
    system: System | None, config: Path | None, data: BagData, topics: ReportTopics, clock: Callable[[float], float]
) -> str:
    """Fig. 7.16: the environment, estimated and true trajectories, zoom-map areas, target sightings."""
    out = []
    env = system.environment if system is not None else None
    if env is None:
        out.append(note("No <Environment> in the configuration: the trajectories are drawn without a map."))
    tracks = []
    estimate = data.poses.get(topics.estimate, [])
    if estimate:
        tracks.append((f"estimated ({topics.estimate})", "tab:blue", [(clock(t), x, y) for t, x, y in estimate]))
    else:
        out.append(_missing("estimated trajectory", [topics.estimate], data, "--pose-topic"))
    truth = next((t for t in topics.truth if data.poses.get(t)), None)
    if truth is not None:
        tracks.append((f"true ({truth})", "tab:green", [(clock(t), x, y) for t, x, y in data.poses[truth]]))
    else:
        out.append(_missing("true trajectory", topics.truth, data, "--truth-topic"))
    zoom = [(clock(t), x, y, w, d) for t, x, y, w, d in data.zoom]
    if not zoom:
        out.append(_missing("zoom-map areas recorded", topics.zoom, data, "--zoom-topic"))
        settings = env.zoom if env is not None else None
        if settings is not None and estimate and settings.max_objects is None:
            zoom = replay_zoom([(clock(t), x, y) for t, x, y in estimate], settings)
            size = f"{settings.width:g} × {settings.depth:g} m"
            rule = f"re-centred within {settings.border:.0%} of its border or after {settings.timeout:g} s, §6.1.3"
            what = "The zoom-map areas drawn are replayed from the estimated trajectory with the configuration's"
            out.append(note(f"{what} <ZoomMap> ({size}, {rule})."))
    sightings = [s for _, message in data.detections.get(topics.fused, []) for s in message]
    target = [(s.x, s.y) for s in sightings if s.x is not None and s.y is not None]
    if env is None and not tracks and not zoom:
        return "".join(out) + note("Nothing to draw for Fig. 7.16.")
    base = config.parent if config is not None else None
    return "".join(out) + png_tag(map_png(env, tracks, zoom, target if len(target) < 5000 else [], base), "Fig. 7.16")


def replay_zoom(track: Sequence[tuple[float, float, float]], settings: ZoomMap) -> list[ZoomArea]:
    """The zoom-map areas a robot following ``track`` ((t, x, y)) gets from ``<ZoomMap>`` (§6.1.3): centred
    on it at the start, again when it comes within ``border`` × the size of the area's edge, and
    after ``timeout`` s (the triggers of plugins/environment/zoom.py; fixed size, no ``maxObjects``)."""
    areas: list[ZoomArea] = []
    for t, x, y in track:
        if areas:
            since, cx, cy, width, depth = areas[-1]
            margin_x, margin_y = width / 2 - abs(x - cx), depth / 2 - abs(y - cy)
            border = margin_x < settings.border * width or margin_y < settings.border * depth
            if not border and t - since < settings.timeout:
                continue
        areas.append((t, x, y, settings.width, settings.depth))
    return areas


def choose_target(data: BagData, topics: ReportTopics, target: str | None) -> tuple[list[str], str]:
    """The terms naming the target object and how it was chosen: given, or the object with the
    greatest summed reliability over the results (recognised most often and most reliably)."""
    if target:
        return target.lower().split(), f"target {target!r} (--target)"
    score: dict[str, float] = {}
    for topic in [topics.fused, *topics.recognition]:
        for _, message in data.detections.get(topic, []):
            best: dict[str, float] = {}
            for seen in message:
                best[seen.name] = max(best.get(seen.name, 0.0), seen.reliability)
            for name, reliability in best.items():
                score[name] = score.get(name, 0.0) + reliability
        if score:
            break
    if not score:
        return [], "no object recognised"
    name = max(score, key=lambda n: (score[n], n))
    return name.lower().split(), f"target {name!r}: the object recognised most reliably (--target to choose another)"


def _best(message: list[Sighting], terms: list[str]) -> Sighting | None:
    matching = [s for s in message if terms and all(t in s.name.lower() for t in terms)]
    return max(matching, key=lambda s: s.reliability) if matching else None


def _nearest(track: Sequence[tuple[float, ...]], t: float) -> tuple[float, ...] | None:
    """The sample of a time-sorted ``(t, …)`` track nearest ``t``, if within :data:`POSE_GAP`."""
    i = bisect_left([p[0] for p in track], t)
    near = [p for p in track[max(0, i - 1) : i + 1] if abs(p[0] - t) <= POSE_GAP]
    return min(near, key=lambda p: abs(p[0] - t)) if near else None


def _approach(data: BagData, topics: ReportTopics, terms: list[str], clock: Callable[[float], float]) -> list[Approach]:
    """(run time, distance, bearing in degrees or None, reliability) of each fused target sighting
    with a robot pose near it: the estimate, else the ground truth."""
    source = next((t for t in [topics.estimate, *topics.truth] if data.poses.get(t)), None)
    if source is None:
        return []
    track, headings = data.poses[source], data.headings.get(source, [])
    found: list[Approach] = []
    for _, message in data.detections.get(topics.fused, []):
        seen = _best(message, terms)
        if seen is None or seen.x is None or seen.y is None:
            continue
        robot = _nearest(track, seen.time)
        if robot is None:
            continue
        dx, dy = seen.x - robot[1], seen.y - robot[2]
        heading = _nearest(headings, seen.time)
        bearing = None
        if heading is not None:  # the target's direction seen from the robot, wrapped to ±180°
            bearing = math.degrees((math.atan2(dy, dx) - heading[1] + math.pi) % (2 * math.pi) - math.pi)
        found.append((clock(seen.time), math.hypot(dx, dy), bearing, seen.reliability))
    return found


def reliability_section(
    data: BagData,
    topics: ReportTopics,
    report: Report,
    target: str | None,
    clock: Callable[[float], float],
    recognising: Collection[str] = (),
) -> str:
    """Fig. 7.19: the target's reliability vs run time on each recognition topic; the robot's distance
    and bearing to the (fused) target vs run time; the fused reliability vs distance. The visits of
    the ``recognising`` states (paths or names: where recognition matters, §7.4.1,
    :func:`.report_topics.recognising_states`) are shaded."""
    present = [t for t in [topics.fused, *topics.recognition] if data.detections.get(t)]
    if not present:
        return _missing("recognition results", [topics.fused, *topics.recognition], data)
    terms, chosen = choose_target(data, topics, target)
    out = [f"<p>{escape(chosen)}.</p>"]
    series = []
    for topic in present:
        best = [_best(m, terms) for _, m in data.detections[topic]]
        points = [(clock(s.time), s.reliability) for s in best if s is not None]
        if points:
            series.append((topic + (" (fused)" if topic == topics.fused else ""), points))
        missed = sum(1 for s in best if s is None)
        out.append(f"<p>{escape(topic)}: target in {len(points)} of {len(best)} results ({missed} without it).</p>")
    approach = _approach(data, topics, terms, clock)
    if not approach:
        out.append(note("No distance or angle to the target: no fused target position with a robot pose near it."))
    shaded = [r for r in report.rows if r.path in recognising or r.state in recognising]
    spans = [(r.state, begin, end) for r in shaded for begin, end in r.spans]
    if not series:
        return "".join(out) + note("The target was never recognised: nothing to plot.")
    return "".join(out) + png_tag(reliability_png(series, approach, spans), "Fig. 7.19")
