"""ckm-plugins: every registered kind with its parameters and ports (the manifests ``verify`` uses).

- ``ckm-plugins list [--long] [--json]``: one line per kind (``CATEGORY.KIND`` and its summary;
  ``--long``: with its Params and ports);
- ``ckm-plugins show KIND…``: a kind's description, Params (type, default, unit, range, doc) and
  ports, then the rest of its class's and its module's documentation and its reference (below);
  ``KIND`` is ``CATEGORY.KIND`` or a kind name registered in one category only;
- ``ckm-plugins markdown [--package NAME]``: the reference page ``docs/plugins.md`` is generated
  from (``--package ckm``: only the kinds this distribution registers);
- ``ckm-plugins interfaces [--markdown]``: the standard service interfaces, each with the kinds that
  implement it and the behavior kinds that use it (``docs/interfaces.md`` is ``--markdown``).

A kind's reference: a kind class may define a classmethod ``reference(form)`` returning a text
generated from its own data (``form`` "text" for ``show``, "markdown" for the page), such as
``hardware.sim``'s device table (D295); ``show`` prints it after the documentation, the page after
the kind's ports.

Exit codes: 0, or 1 when a kind is unknown or cannot be imported (one line on stderr, no traceback).
"""

from __future__ import annotations

import argparse
import inspect
import json
import re
import sys
from collections.abc import Mapping, Sequence
from typing import Any

from .registry import CATEGORIES, Registry, RegistryError, default_registry
from .ros.interface_types import ADAPTATIONS
from .verification.interfaces import STANDARD, Interface, Port, provided_by, uses_of, writes_of
from .verification.manifest import Params, Ports, params_of, ports_of

_NAMES = re.compile(r"^``[\w.-]+``(?:\s*/\s*``[\w.-]+``)*:\s*")
_SEE_MODULE = re.compile(
    r"\s*\((?:see )?(?:the )?module doc(?:string)?\)"
    r"|,? (?:see )?the module doc(?:string)?|;\s*see the module doc(?:string)?"
)
"""A summary's pointer to the module docstring, which ``show`` prints in full below it."""
_TITLES = {
    "hardware": "Hardware backends (`HWChannel/@backend`)",
    "function": "Adaptation functions (`Function/@plugin`)",
    "controller": "Controllers (`Controller/@kind`, `Optional/@kind`)",
    "plugin": "Processing plugins (`SmartResource/Plugin/@kind`)",
    "behavior": "Behaviors (`Behavior/@kind`)",
}


def summary(cls: type[Any]) -> str:
    """The first paragraph of a class's docstring, on one line (without a pointer to the module's)."""
    doc = inspect.getdoc(cls) or ""
    first = " ".join(doc.split("\n\n", 1)[0].split())
    return _SEE_MODULE.sub("", _NAMES.sub("", first))  # "``plugin.resize``: an image …" → "an image …"


def details(cls: type[Any]) -> str:
    """The rest of a kind's documentation: its class docstring after the summary, then its module's
    docstring (where most kinds document their messages, devices and decisions)."""
    rest = (inspect.getdoc(cls) or "").split("\n\n", 1)[1:]
    module = sys.modules.get(cls.__module__)
    about = inspect.getdoc(module) if module is not None else None
    return "\n\n".join(part.strip() for part in (*rest, about or "") if part.strip())


def reference(cls: type[Any], form: str) -> str:
    """A kind's generated reference in ``form`` ("text" or "markdown"); "" when it has none."""
    made = getattr(cls, "reference", None)
    return str(made(form)).strip() if callable(made) else ""


def _params_rows(params: Params) -> list[dict[str, str]]:
    return [
        {
            "name": p.name,
            "type": p.type_name,
            "default": p.default_text(),
            "unit": p.unit,
            "range": p.range_text(),
            "doc": p.doc,
        }
        for p in params.specs.values()
    ]


def _ports_text(ports: Ports) -> list[str]:
    lines = []
    for label, table in (("inputs", ports.inputs), ("outputs", ports.outputs)):
        shown = ", ".join(f"{name}: {value}" for name, value in table.items())
        lines.append(f"{label}: {shown}")
    if ports.sizes:
        lines.append("channel sizes: " + ", ".join(map(str, ports.sizes)))
    return lines


def describe(registry: Registry, category: str, kind: str) -> dict[str, Any]:
    """A kind's manifest as plain data (the JSON of ``show``)."""
    cls = registry.find(category, kind)
    assert cls is not None
    ports = ports_of(cls)
    return {
        "name": f"{category}.{kind}",
        "class": registry.target(category, kind),
        "package": registry.origin(category, kind),
        "summary": summary(cls),
        "details": details(cls),
        "reference": reference(cls, "text"),
        "params": _params_rows(params_of(cls)),
        "inputs": dict(ports.inputs),
        "outputs": dict(ports.outputs),
        "sizes": list(ports.sizes),
        "provides": provided_by(cls),
        "writes": {name: list(fields) for name, fields in writes_of(cls).items()},
        "uses": [
            {"alias": u.alias, "interface": u.interface, "optional": u.optional, "doc": u.doc}
            for u in (uses_of(cls) or ())
        ],
    }


def _uses_text(info: dict[str, Any]) -> list[str]:
    lines = [f"implements interface: {info['provides']}"] if info.get("provides") else []
    lines += [f"writes onto Output {name!r}: {', '.join(fields)}" for name, fields in info.get("writes", {}).items()]
    for use in info.get("uses", ()):
        optional = ", optional" if use["optional"] else ""
        lines.append(f"uses as {use['alias']!r}: {use['interface']} service{optional} ({use['doc']})")
    return lines


def _lookup(registry: Registry, name: str) -> tuple[str, str]:
    category, dot, kind = name.partition(".")
    if dot and category in CATEGORIES:
        if kind in registry.kinds(category):
            return category, kind
        raise LookupError(f"no {category} kind {kind!r} (registered: {', '.join(registry.kinds(category)) or 'none'})")
    found = [(c, k) for c, k in registry.names() if k == name]
    if len(found) == 1:
        return found[0]
    if found:
        raise LookupError(f"{name!r} is registered in several categories: {', '.join(f'{c}.{k}' for c, k in found)}")
    raise LookupError(f"no kind {name!r} is registered (see ckm-plugins list)")


def _show(info: dict[str, Any], full: bool = False) -> str:
    lines = [f"{info['name']}  ({info['class']})", f"  {info['summary']}" if info["summary"] else ""]
    if info["params"]:
        lines.append("  Params:")
        for row in info["params"]:
            unit = f"unit {row['unit']}" if row["unit"] else ""
            facts = ", ".join(x for x in (row["type"], row["default"], unit, row["range"]) if x)
            lines.append(f"    {row['name']} ({facts}): {row['doc']}")
    else:
        lines.append("  Params: none")
    ports = Ports(info["inputs"], info["outputs"], tuple(info["sizes"]))
    lines += [f"  {line}" for line in _ports_text(ports)]
    lines += [f"  {line}" for line in _uses_text(info)]
    text = "\n".join(line for line in lines if line)
    for part in ("details", "reference") if full else ():
        if info.get(part):
            text += "\n\n" + "\n".join(f"  {line}".rstrip() for line in info[part].splitlines())
    return text


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def markdown(registry: Registry, package: str | None = None) -> str:
    """The reference page of the registered kinds (``docs/plugins.md``)."""
    out = [
        "# Registered kinds",
        "",
        "Generated by `ckm-plugins markdown --package ckm` from the kinds' manifests; "
        "`tests/runtime/test_plugins_cli.py` keeps it current. `ckm-validate` checks every "
        "configuration against these declarations (see `docs/writing-plugins.md` to add a kind).",
        "",
        "Value types of ports: a built-in or MessageType name, `number` (one float), `numbers` "
        "(one float per channel element), `mapping` (a dict of fields, fits a MessageType holding every "
        "field the kind writes: docs/interfaces.md), `array` (an n-dimensional array such as an image, "
        "fits only `bytes`), `any` (not checked). "
        "Ranges: `[a, b]` inclusive, `(a, b)` exclusive.",
    ]
    for category in CATEGORIES:
        kinds = [k for k in registry.kinds(category) if package is None or registry.origin(category, k) == package]
        if not kinds:
            continue
        out += ["", f"## {_TITLES[category]}"]
        for kind in kinds:
            info = describe(registry, category, kind)
            out += ["", f"### `{info['name']}`", "", f"`{info['class']}` — {info['summary']}", ""]
            if info["params"]:
                out += ["| Param | type | default | unit | range | meaning |", "| --- | --- | --- | --- | --- | --- |"]
                for row in info["params"]:
                    cells = [f"`{row['name']}`", row["type"], row["default"], row["unit"], row["range"], row["doc"]]
                    out.append("| " + " | ".join(_cell(c) for c in cells) + " |")
            else:
                out.append("No Params.")
            cls = registry.find(category, kind) or object
            out += ["", "Ports: " + "; ".join(_ports_text(ports_of(cls))) + "."]
            out += [f"\n{line[0].upper()}{line[1:]}." for line in _uses_text(info)]
            generated = reference(cls, "markdown")
            out += ["", generated] if generated else []
    return "\n".join(out) + "\n"


def _implementers(registry: Registry, interface: str, package: str | None) -> tuple[list[str], list[str]]:
    """The plugin kinds implementing ``interface`` and the behavior kinds using it (``alias`` in brackets)."""
    kinds, behaviors = [], []
    for category, kind in registry.names():
        if package is not None and registry.origin(category, kind) != package:
            continue
        cls = registry.find(category, kind)
        if category == "plugin" and provided_by(cls) == interface:
            kinds.append(f"{category}.{kind}")
        for use in uses_of(cls) or () if category == "behavior" else ():
            if use.interface == interface:
                behaviors.append(f"{category}.{kind} (as {use.alias!r}{', optional' if use.optional else ''})")
    return kinds, behaviors


def _codes(names: Sequence[str]) -> str:
    return ", ".join(f"`{n}`" for n in names)


def _port_fields(interface: Interface, label: str, port: Port, writers: Mapping[str, type[Any] | None]) -> list[str]:
    """The fields of one port, kind by kind (an Input: what a goal carries), and what its types drop."""
    out, every = [], set(port.fields)
    if label == "Output":
        for kind, cls in writers.items():
            written = writes_of(cls).get(port.name) or port.fields
            every |= set(written)
            out.append(f"- `{kind}` writes {_codes(written)}")
    elif port.fields:
        out.append(f"- a goal carries {_codes(port.fields)}")
    for message in port.messages:
        adaptation = ADAPTATIONS.get(message)
        for name, why in adaptation.dropped.items() if adaptation is not None else ():
            if name in every:
                out.append(f"- on `{message}`, `{name}` is not carried: {why}")
    return [f"{label} `{port.name}`:", "", *out, ""] if out else []


def _interface_section(interface: Interface, kinds: list[str], behaviors: list[str], registry: Registry) -> list[str]:
    out = ["", f"## `{interface.name}`", "", interface.summary, ""]
    out += ["| port | name | message types | what it carries |", "| --- | --- | --- | --- |"]
    for label, ports in (
        ("Input", interface.inputs),
        ("Output", interface.outputs),
        ("Parameter", interface.parameters),
        ("QualityMeasure", interface.measures),
    ):
        out += [f"| {label} | `{port.name}` | {_codes(port.messages) or '—'} | {_cell(port.doc)} |" for port in ports]
    writers = {kind: registry.find("plugin", kind.removeprefix("plugin.")) for kind in kinds}
    fields = [
        line
        for label, ports in (("Input", interface.inputs), ("Output", interface.outputs))
        for port in ports
        for line in _port_fields(interface, label, port, writers)
    ]
    names = {p.name for p in interface.outputs}
    further = [
        f"- `{kind}` Output `{name}`: {_codes(written)}"
        for kind, cls in writers.items()
        for name, written in writes_of(cls).items()
        if name not in names
    ]
    if further:
        fields += ["Further Outputs of its kinds (not the interface's):", "", *further, ""]
    if fields:
        out += ["", "Fields (`a.b` nested, `a[].b` in each element of a list), kind by kind:", "", *fields[:-1]]
    if interface.goals:
        out += ["", f"Goals: {interface.goals}"]
    out += [
        "",
        "Implemented by: "
        + (
            ", ".join(f"`{k}`" for k in kinds)
            or "no kind of this distribution (a `<Service interface=…>` of your own, or a ROS kernel resource)"
        )
        + ".",
    ]
    out += ["", "Used by: " + (", ".join(f"`{b}`" for b in behaviors) or "no behavior kind yet") + "."]
    return out


def interfaces_markdown(registry: Registry, package: str | None = None) -> str:
    """The page of the standard service interfaces (``docs/interfaces.md``)."""
    out = [
        "# Service interfaces",
        "",
        "Generated by `ckm-plugins interfaces --markdown` from `runtime/verification/interfaces.py`; "
        "`tests/runtime/test_plugins_cli.py` keeps it current.",
        "",
        'A `<Service>` is of an interface when it says so (`interface="navigation"`) or when the output '
        "plugin of its profiles implements it; it must then have the interface's Inputs, Outputs, "
        "Parameters and quality measures by these names (their topics are the system's own). A behavior "
        'kind reads the services it needs under fixed aliases (`<Uses service="…" as="nav"/>`); '
        "`ckm-validate` refuses, at its line, a required alias missing, an alias bound to a service of "
        "another interface or of none, and a service of an interface missing one of its ports. Further "
        "`<Uses>` (services a behavior only configures or asks a quality of, for eq. 5.1) are accepted.",
        "",
        "Each port names the ROS 2 types its topic may carry: a standard one (sensor_msgs, nav_msgs, "
        "geometry_msgs) where ROS 2 has one, else one of the `ckm_interfaces` package CKM ships "
        "(docs/ros.md). A standard kind's planar result becomes its port's standard type on the wire and in "
        "the recording (`stamp` in the `header`, a yaw as a quaternion); a topic may also carry a "
        "MessageType of the system's own. Either way `ckm-validate` refuses, at the Output's line, a topic "
        "type that lacks a field its kind writes (the lists below), so nothing is lost silently.",
    ]
    for interface in STANDARD.values():
        out += _interface_section(interface, *_implementers(registry, interface.name, package), registry)
    return "\n".join(out) + "\n"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ckm-plugins", description="List the registered kinds and their manifests.")
    sub = parser.add_subparsers(dest="command", required=True)
    listing = sub.add_parser("list", help="every registered kind, one per line")
    listing.add_argument("--json", action="store_true", help="every kind's manifest as a JSON list")
    listing.add_argument("--long", action="store_true", help="every kind with its Params and ports, as show does")
    show = sub.add_parser("show", help="a kind's description, Params and ports, and its module's documentation")
    show.add_argument("kinds", nargs="+", metavar="KIND", help="CATEGORY.KIND, or KIND when unambiguous")
    show.add_argument("--json", action="store_true", help="as JSON")
    page = sub.add_parser("markdown", help="the reference page docs/plugins.md is generated from")
    page.add_argument("--package", metavar="NAME", help="only the kinds registered by this distribution")
    faces = sub.add_parser("interfaces", help="the standard service interfaces, their kinds and behaviors")
    faces.add_argument("--markdown", action="store_true", help="the page docs/interfaces.md is generated from")
    faces.add_argument("--package", metavar="NAME", help="only the kinds registered by this distribution")
    return parser


def _print_interfaces(registry: Registry, package: str | None, as_markdown: bool) -> None:
    if as_markdown:
        sys.stdout.write(interfaces_markdown(registry, package))
        return
    for interface in STANDARD.values():
        kinds, behaviors = _implementers(registry, interface.name, package)
        ports = [
            f"{label} {p.name}"
            for label, group in (
                ("in", interface.inputs),
                ("out", interface.outputs),
                ("param", interface.parameters),
                ("measure", interface.measures),
            )
            for p in group
        ]
        print(f"{interface.name}: {interface.summary}")
        print(f"  ports: {', '.join(ports)}")
        print(f"  kinds: {', '.join(kinds) or 'none'}")
        print(f"  used by: {', '.join(behaviors) or 'none'}")


def main(argv: Sequence[str] | None = None, registry: Registry | None = None) -> int:
    """Run ``ckm-plugins`` (list, show or markdown) on the kinds the ``kind=`` attributes name.

    Args:
        argv: the command line without the program name (None: ``sys.argv[1:]``).
        registry: the kinds to describe (None: the installed entry points).

    Returns:
        The exit code: 0, or 1 when a kind is unknown or cannot be imported.
    """
    args = _parser().parse_args(argv)
    registry = registry or default_registry()
    try:
        if args.command == "markdown":
            sys.stdout.write(markdown(registry, args.package))
        elif args.command == "interfaces":
            _print_interfaces(registry, args.package, args.markdown)
        elif args.command == "list":
            names = registry.names()
            if args.json:
                print(json.dumps([describe(registry, c, k) for c, k in names], indent=2))
            elif args.long:
                print("\n\n".join(_show(describe(registry, c, k)) for c, k in names))
            else:
                width = max((len(c) + len(k) + 1 for c, k in names), default=0)
                for category, kind in names:
                    cls = registry.find(category, kind)
                    print(f"{category}.{kind:<{width - len(category) - 1}}  {summary(cls) if cls else ''}")
        else:
            infos = [describe(registry, *_lookup(registry, name)) for name in args.kinds]
            print(json.dumps(infos, indent=2) if args.json else "\n\n".join(_show(info, full=True) for info in infos))
    except (LookupError, RegistryError) as exc:
        print(f"ckm-plugins: {exc.args[0] if exc.args else exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
