"""Includes, strict and lax modes, loading from memory."""

from __future__ import annotations

from pathlib import Path

import pytest

import ckmconf
from ckmconf import ConfigError

HEAD = '<?xml version="1.0"?>\n'


def write(folder: Path, name: str, body: str, root: str = "Part", attrs: str = 'version="1.0"') -> Path:
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f'{HEAD}<{root} xmlns="urn:ckm:1" {attrs}>\n{body}\n</{root}>\n')
    return path


def system(folder: Path, body: str) -> Path:
    return write(folder, "system.xml", body, "System", 'version="1.0" name="sys"')


NODE = '<Node name="{name}"><Topic name="/{name}/out" type="float64"/></Node>'


def test_diamond_includes_are_read_once(tmp_path: Path) -> None:
    write(tmp_path, "base.xml", NODE.format(name="base"))
    write(tmp_path, "left.xml", '<Include href="base.xml"/>\n' + NODE.format(name="left"))
    write(tmp_path, "sub/right.xml", '<Include href="../base.xml"/>\n' + NODE.format(name="right"))
    path = system(tmp_path, '<Include href="left.xml"/><Include href="sub/right.xml"/>' + NODE.format(name="top"))
    result = ckmconf.load(path, strict=False)
    assert result.errors == []
    assert result.system is not None
    # Included parts first, depth first, then the including file's own content.
    assert [n.name for n in result.system.nodes] == ["left", "base", "right", "top"]
    assert len(result.files) == 4


def test_include_cycle(tmp_path: Path) -> None:
    write(tmp_path, "a.xml", '<Include href="b.xml"/>')
    write(tmp_path, "b.xml", '<Include href="a.xml"/>')
    path = system(tmp_path, '<Include href="a.xml"/>')
    result = ckmconf.load(path, strict=False)
    assert [e.message for e in result.errors] == ["include cycle: a.xml → b.xml → a.xml"]
    assert result.errors[0].file.endswith("a.xml")  # where the cycle begins
    assert result.system is None


def test_missing_include_points_at_the_include(tmp_path: Path) -> None:
    path = system(tmp_path, '<Include href="nowhere.xml"/>')
    with pytest.raises(ConfigError) as caught:
        ckmconf.load(path)
    assert caught.value.message == "cannot include nowhere.xml: file not found"
    assert (caught.value.line, caught.value.xpath) == (3, "/System[@name='sys']/Include")


def test_only_parts_can_be_included(tmp_path: Path) -> None:
    write(tmp_path, "other.xml", "", "System", 'version="1.0" name="other"')
    result = ckmconf.load(system(tmp_path, '<Include href="other.xml"/>'), strict=False)
    assert [e.message for e in result.errors] == ["other.xml holds a System; only a Part can be included"]


def test_singletons_across_files(tmp_path: Path) -> None:
    write(tmp_path, "net.xml", "<Network/>")
    result = ckmconf.load(system(tmp_path, '<Include href="net.xml"/><Network heartbeat="1"/>'), strict=False)
    assert len(result.errors) == 1
    assert result.errors[0].message.startswith("Network is defined twice (first at ")
    assert result.errors[0].file.endswith("system.xml")


def test_errors_in_included_files_name_that_file(tmp_path: Path) -> None:
    write(tmp_path, "bad.xml", '<Node name="n" kind="heavy"/>')
    result = ckmconf.load(system(tmp_path, '<Include href="bad.xml"/>'), strict=False)
    assert [str(e) for e in result.errors] == [
        f"{tmp_path / 'bad.xml'}:3:16: /Part/Node[@name='n']/@kind: invalid kind 'heavy': must be one of light, service"
    ]


def test_strict_raises_the_first_and_lax_returns_all(tmp_path: Path) -> None:
    body = '<Node name="a"/><Node name="a"/><Node name="b"/><Node name="b"/>'
    path = system(tmp_path, body)
    result = ckmconf.load(path, strict=False)
    assert [e.message for e in result.errors] == [
        "duplicate node 'a' in the system (first at line 3)",
        "duplicate node 'b' in the system (first at line 3)",
    ]
    with pytest.raises(ConfigError) as caught:
        ckmconf.load(path)
    assert caught.value == result.errors[0]


def test_a_part_loads_on_its_own(tmp_path: Path) -> None:
    loaded = ckmconf.load(write(tmp_path, "nodes.xml", NODE.format(name="n")))
    assert loaded.name == "nodes"
    assert [n.name for n in loaded.nodes] == ["n"]


def test_load_bytes_resolves_includes_next_to_the_given_path(tmp_path: Path) -> None:
    write(tmp_path, "net.xml", "<Network/>")
    text = b'<System xmlns="urn:ckm:1" version="1.0" name="m"><Include href="net.xml"/></System>'
    loaded = ckmconf.load_bytes(text, str(tmp_path / "in-memory.xml"))
    assert loaded.network is not None


def test_unsupported_version(tmp_path: Path) -> None:
    path = write(tmp_path, "future.xml", "<Whatever/>", "System", 'version="2.0" name="f"')
    with pytest.raises(ConfigError) as caught:
        ckmconf.load(path)
    assert caught.value.message == "unsupported model version '2.0': this release reads 1.x"


def test_read_document_keeps_includes(tmp_path: Path) -> None:
    write(tmp_path, "net.xml", "<Network/>")
    document = ckmconf.read_document(system(tmp_path, '<Include href="net.xml"/>'))
    assert [i.href for i in document.includes] == ["net.xml"]
    assert document.network is None


def test_dump_is_atomic_and_reloadable(tmp_path: Path) -> None:
    loaded = ckmconf.load(system(tmp_path, NODE.format(name="n")))
    target = tmp_path / "out.xml"
    ckmconf.dump(loaded, target)
    assert ckmconf.load(target) == loaded
    assert not list(tmp_path.glob(".*.tmp"))


def test_out_of_order_element_is_found_despite_comments(tmp_path: Path) -> None:
    path = system(tmp_path, '<!-- one -->\n<!-- two -->\n<Node name="a"/>\n<Topic name="/t" type="float64"/>')
    result = ckmconf.load(path, strict=False)
    assert [(e.line, e.xpath) for e in result.errors] == [(6, "/System[@name='sys']/Topic[@name='/t']")]
    assert result.errors[0].message.startswith("Topic is out of place: System holds its children in this order: ")


NODE_WITH_ALARM = """<Node name="n">
  <Partition name="p" restart="never"/>
  <Topic name="/in" type="float64"/><Topic name="/out" type="float64"/>
  <Controller name="c" kind="pid" period="0.1"><Input topic="/in"/><Output topic="/out"/></Controller>
  <Monitor>{alarm}</Monitor>
</Node>"""


@pytest.mark.parametrize(
    "alarm,message",
    [
        (
            '<Alarm name="x" measure="cpu" above="0.9" action="delegate" target="c"/>',
            "controller 'c' is not delegable (set delegable=\"true\")",
        ),
        (
            '<Alarm name="x" measure="partition-crash" partition="p" action="restart"/>',
            "partition 'p' has restart=\"never\"; it cannot be restarted",
        ),
        (
            '<Alarm name="x" measure="partition-crash" partition="p" above="0"/>',
            "a partition-crash alarm fires on every crash and takes no threshold",
        ),
        ('<Alarm name="x" measure="cpu" above="0.9" task="c"/>', "task does not apply to a cpu alarm"),
        ('<Alarm name="x" measure="memory" above="0.9" topic="/in"/>', "topic does not apply to a memory alarm"),
        (
            '<Alarm name="x" measure="cpu" above="0.9" partition="p"/>',
            "partition only applies to partition-crash alarms and the restart action",
        ),
    ],
)
def test_alarm_coherence(tmp_path: Path, alarm: str, message: str) -> None:
    result = ckmconf.load(system(tmp_path, NODE_WITH_ALARM.format(alarm=alarm)), strict=False)
    assert [e.message for e in result.errors] == [message]


def test_zenoh_settings_need_the_zenoh_transport(tmp_path: Path) -> None:
    result = ckmconf.load(
        system(tmp_path, '<Network transport="multipeer"><Zenoh mode="client"/></Network>'), strict=False
    )
    assert [e.message for e in result.errors] == ['Zenoh settings are only used with transport="zenoh"']


def test_prism_heights_are_relative_to_the_object_pose(tmp_path: Path) -> None:
    env = """<Environment name="e"><Map xmin="0" ymin="0" xmax="5" ymax="5" height="3"/>
      <Semantic tag="box"/>
      <Object name="high" tag="box"><Pose x="1" y="1" z="2.5"/>
        <Geometry25D><Prism zmax="1"><Rectangle width="0.2" depth="0.2"/></Prism></Geometry25D></Object>
    </Environment>"""
    result = ckmconf.load(system(tmp_path, env), strict=False)
    assert [e.message for e in result.errors] == ["the object reaches 3.5 m, above the map height (3 m)"]


PLAN = """<Node name="pc"/>
<Behavior name="b" kind="k"/>
<Mission name="m1" initial="s"><State name="s" behavior="b"/><Final name="f"/>
  <Transition from="s" to="f" when="{when}"/></Mission>
<Mission name="m2" initial="s"><State name="s" behavior="b"/><Final name="f"/><Transition from="s" to="f"/></Mission>
<Plan name="p"><Agent name="a1" node="pc" mission="m1"/><Agent name="a2" node="pc" mission="m2"/>
  <Signal name="go" agent="a2" state="s"{signal_attrs}/>
  <Dependency agent="a1" state="s" signal="go"/></Plan>"""


@pytest.mark.parametrize(
    "when,signal_attrs,messages",
    [
        ("signal('go')", "", []),
        (
            "done()",
            "",
            [
                "state 's' never waits for 'go': use signal('go') in a transition out of it, "
                'or give its behavior an Input with signal="go"'
            ],
        ),
        (
            "signal('og')",
            "",
            [
                "signal 'og' does not exist in any plan (defined: go)",
                "state 's' never waits for 'go': use signal('go') in a transition out of it, "
                'or give its behavior an Input with signal="go"',
            ],
        ),
        (
            "signal('go')",
            ' topic="/nowhere"',
            ["external topic '/nowhere' does not exist in the system (none is defined)"],
        ),
    ],
)
def test_plan_signals(tmp_path: Path, when: str, signal_attrs: str, messages: list[str]) -> None:
    path = system(tmp_path, PLAN.format(when=when, signal_attrs=signal_attrs))
    assert [e.message for e in ckmconf.load(path, strict=False).errors] == messages


def test_signal_names_wait_for_a_plan(tmp_path: Path) -> None:
    # A missions-only part cannot know the plan's signals yet: they are checked once a plan is loaded.
    body = PLAN.format(when="signal('later')", signal_attrs="").split("<Plan")[0]
    assert ckmconf.load(write(tmp_path, "missions.xml", body), strict=False).errors == []


def test_topic_suggestions_match_the_last_segment(tmp_path: Path) -> None:
    body = (
        '<Node name="n"><HWChannel name="c" direction="in"/><Topic name="/kobuki/wheel_odom" type="float64"/>'
        '<Sensor name="s" channel="c" topic="wheel_odom" period="0.1"/></Node>'
    )
    message = ckmconf.load(system(tmp_path, body), strict=False).errors[0].message
    assert message == "topic 'wheel_odom' does not exist in node 'n'; did you mean '/kobuki/wheel_odom'?"


def test_problem_count_is_bounded(tmp_path: Path) -> None:
    path = system(tmp_path, "<Junk/>\n" * 5000)
    errors = ckmconf.load(path, strict=False).errors
    assert len(errors) == 101
    assert errors[0].message.startswith("unexpected element 'Junk' in System (allowed: Include, Network, ")
    assert (errors[-1].line, errors[-1].message) == (103, "more problems from here on; only the first 100 are listed")


def test_very_large_invalid_files_are_reported_by_libxml2(tmp_path: Path) -> None:
    # Past 100,000 elements xmlschema would take seconds; libxml2's finding is located the same way.
    nodes = '<Node name="n{i}"><Topic name="t" type="float64" scope="internal"/></Node>\n'
    body = "".join(nodes.format(i=i) for i in range(60_000)) + '<Node name="bad" kind="heavy"/>'
    errors = ckmconf.load(system(tmp_path, body), strict=False).errors
    assert len(errors) == 1
    assert (errors[0].line, errors[0].xpath) == (60_003, "/System[@name='sys']/Node[@name='bad']")
    assert "heavy" in errors[0].message and "kind" in errors[0].message
