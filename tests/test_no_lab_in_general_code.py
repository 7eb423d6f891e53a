"""The lab leaves the general code (issue M point 4, D272): no module of the toolkit's packages takes a
value of the thesis' lab — its robots, objects, links, joints, topics or files — as a literal, and none
imports the lab's package. What is truly the lab's lives in examples/ckm-lab (``ckm_lab``) and
configs/usecase. Docstrings and prose may cite the lab as an example; a literal that *is* one of its
names (a default, a lookup key, a path) may not."""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

from tests.conftest import REPO

GENERAL = ("ckmconf", "runtime", "plugins", "editor")
"""The toolkit's packages (benchmarks reproduce the thesis' experiments on the lab, so they may name it)."""
LAB_NAMES = frozenset({
    "turtlebot", "nao", "kobuki", "xtion", "cylinder_red_stripes", "cylinder_blue_dots", "cylinder_green_checker",
    "drop_table", "workbench", "gripper_tool_link", "HeadYaw", "HeadPitch", "arm_poses.yml", "lab.xml",
    "arm_shoulder_pan_joint", "wheel_left_joint", "camera_rgb_optical_frame",
})  # fmt: skip
LAB_PREFIXES = ("/nav/", "/recog", "/kobuki", "/nao/", "/turtlebot", "/arm/", "configs/usecase", "usecase/")
"""The lab's topic namespaces and its configuration directory."""


def _docstrings(tree: ast.AST) -> set[int]:
    """The ids of the string constants that are docstrings (module, class, function, attribute)."""
    found: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            found.add(id(node.value))
    return found


def _lab_literals(path: Path) -> Iterator[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    docs = _docstrings(tree)
    where = path.relative_to(REPO) if path.is_relative_to(REPO) else path.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            value = node.value.strip()
            if value in LAB_NAMES or value.startswith(LAB_PREFIXES) or "configs/usecase" in value:
                yield f"{where}:{node.lineno}: {value!r}"
        elif isinstance(node, ast.Import | ast.ImportFrom):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
            if any(n == "ckm_lab" or n.startswith("ckm_lab.") for n in names):
                yield f"{where}:{node.lineno}: imports ckm_lab"


def test_no_general_module_names_the_lab() -> None:
    found = [hit for package in GENERAL for path in sorted((REPO / package).rglob("*.py"))
             for hit in _lab_literals(path)]  # fmt: skip
    assert found == []


def test_the_check_finds_a_lab_default(tmp_path: Path) -> None:
    """The scan is not blind: a lab default, a lab topic and an import of the lab are each found."""
    sample = tmp_path / "sample.py"
    sample.write_text('"""A module citing the turtlebot in prose."""\nimport ckm_lab.arm\n'
                      'LINK = "gripper_tool_link"\nTOPIC = "/nav/status"\n', encoding="utf-8")
    assert sorted(hit.split(": ", 1)[1] for hit in _lab_literals(sample)) == [
        "'/nav/status'", "'gripper_tool_link'", "imports ckm_lab"]
