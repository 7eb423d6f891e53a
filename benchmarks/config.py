"""ckm-bench config: validate and load a generated system of 1,000 nodes."""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import ckmconf
from ckmconf.schema import schema, validate
from ckmconf.source import Limits, read_source

from .generate import system_xml


def run(nodes: int = 1000, repeats: int = 3) -> dict[str, Any]:
    """Time the XSD validation and the load of a generated ``<System>`` of ``nodes`` nodes (§3.1.5.2).

    Returns:
        Its size, the schema compile time, and the median validation and load times (s) of ``repeats`` runs.
    """
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "generated.xml"
        path.write_text(system_xml(nodes))
        started = time.perf_counter()
        schema()
        schema_s = time.perf_counter() - started
        started = time.perf_counter()
        first = ckmconf.load(path)
        cold_s = time.perf_counter() - started + schema_s
        validate_times, load_times = [], []
        for _ in range(repeats):
            started = time.perf_counter()
            source = read_source(str(path), Limits())
            problems = validate(source)
            validate_times.append(time.perf_counter() - started)
            assert not problems
            started = time.perf_counter()
            system = ckmconf.load(path)
            load_times.append(time.perf_counter() - started)
            assert system == first
        elements = sum(1 for _ in source.root.iter())
        return {
            "nodes": len(first.nodes),
            "elements": elements,
            "bytes": path.stat().st_size,
            "schema_compile_s": round(schema_s, 4),
            "validate_s": round(statistics.median(validate_times), 4),
            "load_s": round(statistics.median(load_times), 4),
            "cold_load_s": round(cold_s, 4),
        }


def describe(result: dict[str, Any]) -> list[tuple[str, str]]:
    """The rows of ``ckm-bench config``'s table."""
    return [
        ("nodes", str(result["nodes"])),
        ("elements / bytes", f"{result['elements']} / {result['bytes']}"),
        ("schema compile (once per process)", f"{result['schema_compile_s']:.3f} s"),
        ("parse + XSD validation", f"{result['validate_s']:.3f} s"),
        ("full load (XSD + records + cross-reference checks)", f"{result['load_s']:.3f} s"),
        ("cold load (first in a process, with schema compile)", f"{result['cold_load_s']:.3f} s"),
    ]
