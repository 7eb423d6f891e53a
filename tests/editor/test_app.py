"""The editor through its UI, offscreen (pytest-qt): build, undo, validate live, draw a mission,
save, re-open, screenshot. Settings live in a temporary file, never in the user's."""

from __future__ import annotations

from pathlib import Path

import pytest
from PySide6.QtCore import QSettings
from PySide6.QtWidgets import QMessageBox
from pytestqt.qtbot import QtBot

import ckmconf
from editor.app import MainWindow, main
from editor.document import Document, Element, local

REPO = Path(__file__).resolve().parents[2]
LAB = REPO / "configs" / "usecase" / "lab.xml"
EXAMPLES = REPO / "configs" / "examples"


@pytest.fixture
def settings(tmp_path: Path) -> QSettings:
    return QSettings(str(tmp_path / "editor.ini"), QSettings.Format.IniFormat)


def window(qtbot: QtBot, settings: QSettings, path: Path | None = None, answer: str = "Discard") -> MainWindow:
    chosen = getattr(QMessageBox.StandardButton, answer)
    win = MainWindow(path, settings=settings, ask=lambda parent, name: chosen)
    qtbot.addWidget(win)
    return win


def child(element: Element, tag: str, name: str | None = None) -> Element:
    for c in element:
        if isinstance(c.tag, str) and local(c) == tag and (name is None or c.get("name") == name):
            return c
    raise AssertionError(f"no {tag} {name or ''}")


def test_build_a_system_from_an_empty_document_and_save_it(qtbot: QtBot, settings: QSettings, tmp_path: Path) -> None:
    win = window(qtbot, settings)
    root = win.document.main.root
    # Through the tree's "Add" actions and the form, as a user would.
    topic = win.tree.add_child(root, "Topic")
    win.tree.select(topic)
    assert win.form.commit("name", "/speed")
    assert win.form.commit("type", "float64")
    node = win.tree.add_child(root, "Node")
    win.tree.select(node)
    assert win.form.commit("name", "base")
    assert [local(c) for c in root if isinstance(c.tag, str)] == ["Topic", "Node"]  # the XSD's order
    target = tmp_path / "built.xml"
    win.save_as(target)
    assert not win.document.modified and win.windowTitle().startswith("built.xml")
    system = ckmconf.load(target)
    assert [n.name for n in system.nodes] == ["base"] and [t.name for t in system.topics] == ["/speed"]
    assert win.recent()[0] == str(target.resolve())
    # Re-opened and saved again with no edit: byte for byte the same file.
    before = target.read_bytes()
    assert win.open_path(target)
    win.save()
    assert target.read_bytes() == before


def test_undo_and_redo_round_trip(qtbot: QtBot, settings: QSettings) -> None:
    win = window(qtbot, settings, EXAMPLES / "network_multipeer.xml")
    original = win.document.main.to_bytes()
    node = child(win.document.main.root, "Network")
    win.tree.select(node)
    win.document.set_attribute(node, "heartbeat", "0.4")
    added = win.tree.add_child(win.document.main.root, "Topic")
    assert win.document.main.to_bytes() != original and win.document.modified
    stack = win.document.undo
    while stack.canUndo():
        stack.undo()
    assert win.document.main.to_bytes() == original and not win.document.modified
    while stack.canRedo():
        stack.redo()
    assert added.getparent() is win.document.main.root and node.get("heartbeat") == "0.4"


def test_the_form_refuses_invalid_values_with_the_reason(qtbot: QtBot, settings: QSettings) -> None:
    win = window(qtbot, settings, EXAMPLES / "network_multipeer.xml")
    network = child(win.document.main.root, "Network")
    win.tree.select(network)
    before = network.get("transport")
    assert not win.form.commit("transport", "carrier-pigeon")
    assert network.get("transport") == before
    assert "carrier-pigeon" in win.form.error.text()
    assert not win.document.modified


def test_problems_show_a_broken_reference_and_clear_when_fixed(
    qtbot: QtBot, settings: QSettings, tmp_path: Path
) -> None:
    source = (REPO / "configs" / "examples" / "closed_loop.xml").read_bytes()
    path = tmp_path / "loop.xml"
    path.write_bytes(source)
    win = window(qtbot, settings, path)
    assert win.document.problems == []
    sensor = next(e for e in win.document.main.root.iter("{urn:ckm:1}Sensor"))
    good = sensor.get("channel")
    win.document.set_attribute(sensor, "channel", "nowhere")
    problems = win.document.validate()
    assert any("nowhere" in p.message for p in problems)
    listed = win.problems.problems()
    assert listed and win.document.find(listed[0]) is sensor  # a click selects the sensor
    win.problems.chosen.emit(sensor)
    assert win.tree.current_element() is sensor
    win.document.set_attribute(sensor, "channel", good)
    assert win.document.validate() == [] and win.problems.problems() == []


def test_a_mission_drawn_on_the_canvas_saves_as_the_hfsm(qtbot: QtBot, settings: QSettings, tmp_path: Path) -> None:
    path = tmp_path / "plan.xml"
    path.write_bytes((REPO / "configs" / "examples" / "plan_two_agents.xml").read_bytes())
    win = window(qtbot, settings, path)
    win.open_mission("Fetch")
    canvas = win.canvas
    assert set(canvas.nodes) == {"WAIT", "APPR", "done", "gave-up"} and len(canvas.arrows) == 3
    state = canvas.add_state("RETREAT")
    assert state is not None
    state.set("behavior", "APPR")
    assert canvas.connect_states("APPR", "RETREAT", "failed()") is not None
    assert canvas.connect_states("RETREAT", "gave-up") is not None
    assert canvas.connect_states("done", "WAIT") is None  # nothing leaves a final
    win.save()
    mission = ckmconf.load(path).mission("Fetch")
    assert mission is not None
    assert [s.name for s in mission.states] == ["WAIT", "APPR", "RETREAT"]
    edges = [(t.from_, t.to, t.when) for t in mission.transitions]
    assert edges[-2:] == [("APPR", "RETREAT", "failed()"), ("RETREAT", "gave-up", "done()")]
    # The drawn transitions are on the canvas too, and the nested mission of the Nao opens.
    assert len(win.canvas.arrows) == 5
    win.open_mission("Watch")
    assert set(win.canvas.nodes) == {"SEARCH", "over", "gave-up"}


def test_unsaved_changes_are_asked_about(qtbot: QtBot, settings: QSettings) -> None:
    win = window(qtbot, settings, EXAMPLES / "network_multipeer.xml", answer="Cancel")
    win.document.set_attribute(child(win.document.main.root, "Network"), "heartbeat", "0.3")
    assert not win.close()  # cancelled: the window stays
    win.ask = lambda parent, name: QMessageBox.StandardButton.Discard
    assert win.close()


def test_screenshots_of_the_use_case_render(tmp_path: Path) -> None:
    for view in ("tree", "mission:Agent1Fetch", "plan", "topics"):
        target = tmp_path / f"{view.replace(':', '-')}.png"
        assert main([str(LAB), "--screenshot", str(target), "--view", view]) == 0
        assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and target.stat().st_size > 20_000


def test_a_missing_file_is_one_line(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert main([str(tmp_path / "nope.xml"), "--screenshot", str(tmp_path / "x.png")]) == 1
    assert "no such file" in capsys.readouterr().err


def test_document_new_elements_are_indented_like_their_siblings() -> None:
    document = Document(
        None,
        b'<?xml version="1.0"?>\n<System xmlns="urn:ckm:1" version="1.0" name="s">\n  <Node name="a"/>\n</System>\n',
    )
    document.insert(document.root, 1, document.new_element("Node", {"name": "b"}))
    assert document.to_bytes().decode().endswith('  <Node name="a"/>\n  <Node name="b"/>\n</System>\n')
    document.undo.undo()
    assert document.to_bytes().decode().endswith('  <Node name="a"/>\n</System>\n')


def test_a_split_configuration_is_edited_across_its_files(qtbot: QtBot, settings: QSettings, tmp_path: Path) -> None:
    import shutil

    for path in (REPO / "configs" / "usecase").glob("*.xml"):
        shutil.copy(path, tmp_path / path.name)
    (tmp_path / "models").mkdir()
    for path in (REPO / "configs" / "usecase" / "models").iterdir():
        shutil.copy(path, tmp_path / "models" / path.name)
    win = window(qtbot, settings, tmp_path / "lab.xml")
    workspace = win.document
    assert {p.name for p in workspace.documents} == {
        "network.xml", "nodes.xml", "resources.xml", "behaviors.xml", "missions.xml", "plan.xml", "environment.xml",
    }  # fmt: skip
    assert workspace.problems == []
    # The nested mission of Fig. 7.12 lives in missions.xml and opens on the canvas.
    win.open_mission("Navigation")
    assert set(win.canvas.nodes) == {"NAV", "WAIT", "arrived", "failed"}
    wait = win.canvas.nodes["WAIT"].element
    workspace.set_attribute(wait, "behavior", "NO_SUCH_BEHAVIOR")
    problems = workspace.validate()
    assert problems and problems[0].file == str((tmp_path / "missions.xml").resolve())
    assert workspace.find(problems[0]) is wait
    workspace.set_attribute(wait, "timeout", "99")
    workspace.set_attribute(wait, "behavior", "WAIT")
    assert workspace.validate() == []
    before = {p.name: p.read_bytes() for p in tmp_path.glob("*.xml")}
    assert win.save()
    after = {p.name: p.read_bytes() for p in tmp_path.glob("*.xml")}
    assert [name for name in before if before[name] != after[name]] == ["missions.xml"]
    assert b'<State name="WAIT" behavior="WAIT" timeout="99"/>' in after["missions.xml"]
    assert not workspace.modified


def test_plan_deadlocks_show_in_the_problems_panel_at_their_dependency(
    qtbot: QtBot, settings: QSettings, tmp_path: Path
) -> None:
    import shutil

    path = tmp_path / "deadlock_two.xml"
    shutil.copy(REPO / "tests" / "data" / "plans" / "deadlock_two.xml", path)
    win = window(qtbot, settings, path)
    problems = [p for p in win.document.validate() if p.source == "plan"]
    assert [(p.line, p.column) for p in problems] == [(29, 5), (30, 5)]
    assert "[deadlock] deadlock among 2 agent(s) (a, b)" in problems[0].message
    listed = [p for p in win.problems.problems() if p.source == "plan"]
    assert listed == problems
    element = win.document.find(problems[0])
    assert element is not None and local(element) == "Dependency" and element.get("agent") == "a"
