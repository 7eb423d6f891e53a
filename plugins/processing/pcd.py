"""PCD files of the depth classifier's model (thesis §7.4.1): labelled shape descriptors as ASCII PCD v0.7.

``format_pcd`` writes a ``ShapeModel`` (the file the classifier's Param ``model`` names),
``read_pcd`` reads one back for ``plugin.kdtree-shape-classifier``; a malformed file is a
``PcdError`` naming its file and line.
"""

from __future__ import annotations

import functools
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn

import numpy as np
import numpy.typing as npt

from .descriptor import DESCRIPTOR_FIELDS, FloatArray

PCD_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")
MAX_PCD_BYTES = 16 * 1024 * 1024


class PcdError(ValueError):
    """A malformed model file; the text is ``FILE:LINE: message``."""

    def __init__(self, path: str, line: int, message: str) -> None:
        super().__init__(f"{path}:{line}: {message}")
        self.path, self.line = path, line


@dataclass(frozen=True)
class ShapeModel:
    """Labelled training descriptors: ``descriptors`` (N, F), ``labels`` (N,) indices into ``names``."""

    fields: tuple[str, ...]
    descriptors: FloatArray
    labels: npt.NDArray[np.int64]
    names: Mapping[int, str]


def format_pcd(model: ShapeModel, comments: Sequence[str] = ()) -> str:
    """The model as an ASCII PCD v0.7 text: one point per sample, the label as the last field."""
    n, fields = len(model.labels), (*model.fields, "label")
    lines = [
        "# .PCD v0.7 - Point Cloud Data file format",
        "# labels: " + " ".join(f"{i}={name}" for i, name in sorted(model.names.items())),
        *(f"# {text}" for text in comments),
        "VERSION 0.7",
        "FIELDS " + " ".join(fields),
        "SIZE " + " ".join(["4"] * len(fields)),
        "TYPE " + " ".join(["F"] * len(model.fields) + ["U"]),
        "COUNT " + " ".join(["1"] * len(fields)),
        f"WIDTH {n}",
        "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {n}",
        "DATA ascii",
    ]
    for row, label in zip(model.descriptors, model.labels, strict=True):
        lines.append(" ".join(f"{x:.4f}" for x in row) + f" {int(label)}")
    return "\n".join(lines) + "\n"


def _labels(text: str, fail: Callable[[str], NoReturn]) -> dict[int, str]:
    names: dict[int, str] = {}
    for item in text.split():
        match = re.fullmatch(r"(\d+)=([A-Za-z_][\w-]*)", item)
        if match is None:
            fail(f"bad label {item!r} in '# labels:' (expected INDEX=NAME)")
        index = int(match.group(1))
        if index in names:
            fail(f"label {index} is named twice")
        names[index] = match.group(2)
    if not names:
        fail("'# labels:' names no label")
    return names


def read_pcd(path: str | os.PathLike[str], fields: Sequence[str] = DESCRIPTOR_FIELDS) -> ShapeModel:
    """Read a labelled descriptor model (as written by ``format_pcd``); PcdError names the file and line.

    Only what the model needs is accepted: DATA ascii, one value per field, the given ``fields``
    (type F) then ``label`` (type U or I), labels named in a ``# labels: 0=name …`` comment, finite
    values. Plain string splitting and float()/int(): nothing in the file is evaluated.
    """
    name = os.fspath(path)

    def fail(line: int, message: str) -> NoReturn:
        raise PcdError(name, line, message)

    size = Path(path).stat().st_size
    if size > MAX_PCD_BYTES:
        fail(0, f"file of {size} bytes exceeds {MAX_PCD_BYTES}")
    try:
        lines = Path(path).read_text(encoding="ascii").splitlines()
    except UnicodeDecodeError:
        fail(0, "not an ASCII file")
    header: dict[str, list[str]] = {}
    names: dict[int, str] | None = None
    expected = (*fields, "label")
    number = 0
    for number, raw in enumerate(lines, 1):
        line = raw.strip()
        if line.startswith("#") and line[1:].strip().startswith("labels:"):
            names = _labels(line[1:].strip()[len("labels:") :], functools.partial(fail, number))
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        want = PCD_KEYS[len(header)]
        if key != want:
            fail(number, f"expected {want}, found {key!r}")
        header[key] = values
        if key == "VERSION" and values not in (["0.7"], [".7"]):
            fail(number, f"unsupported VERSION {' '.join(values)!r} (expected 0.7)")
        elif key == "FIELDS" and tuple(values) != expected:
            fail(number, f"FIELDS {' '.join(values)!r} are not the descriptor's ({' '.join(expected)})")
        elif key in ("SIZE", "TYPE", "COUNT") and len(values) != len(expected):
            fail(number, f"{key} has {len(values)} entries for {len(expected)} fields")
        elif key == "TYPE" and (any(t != "F" for t in values[:-1]) or values[-1] not in ("U", "I")):
            fail(number, "TYPE must be F for the descriptor fields and U or I for the label")
        elif key == "COUNT" and any(v != "1" for v in values):
            fail(number, "every COUNT must be 1")
        elif key in ("WIDTH", "HEIGHT", "POINTS") and not (len(values) == 1 and values[0].isdigit()):
            fail(number, f"{key} must be a non-negative integer")
        elif key == "DATA":
            if values != ["ascii"]:
                fail(number, f"DATA {' '.join(values)!r} is not supported (only ascii)")
            break
    else:
        fail(number, "the header ends before DATA" if header else "no PCD header")
    if names is None:
        fail(number, "no '# labels: 0=name …' comment before DATA")
    points = int(header["POINTS"][0])
    if int(header["WIDTH"][0]) * int(header["HEIGHT"][0]) != points:
        fail(number, f"WIDTH × HEIGHT is not POINTS ({points})")
    rows: list[list[float]] = []
    labels: list[int] = []
    for index, raw in enumerate(lines[number:], number + 1):
        values = raw.split()
        if not values:
            continue
        if len(values) != len(expected):
            fail(index, f"{len(values)} values for {len(expected)} fields")
        try:
            row = [float(x) for x in values[:-1]]
            label = int(values[-1])
        except ValueError:
            fail(index, f"not a number in {raw.strip()!r}")
        if not all(math.isfinite(x) for x in row):
            fail(index, "a value is not finite")
        if label not in names:
            fail(index, f"label {label} is not in '# labels:' ({', '.join(map(str, sorted(names)))})")
        rows.append(row)
        labels.append(label)
    if len(rows) != points:
        fail(len(lines), f"{len(rows)} data rows for POINTS {points}")
    if not rows:
        fail(number, "the model has no samples")
    return ShapeModel(tuple(fields), np.array(rows, dtype=np.float64), np.array(labels, dtype=np.int64), names)
