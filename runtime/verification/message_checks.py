"""The field part of ``verify``: a service Output's topic type holds every field its kind writes (D277).

A mapping fits any MessageType by value type (:mod:`.types`), so a topic whose MessageType lacks a
field the output plugin writes would lose it silently on the wire and in the recording. What a kind
writes is known from its declaration (``WRITES``: Output name → field paths) or, without one, from
the port of its interface the Output is (:class:`~.interfaces.Port` ``fields``). For each
``<Output>`` of a service, :class:`MessageChecks` walks those fields (``pose.x`` nested,
``objects[].name`` in a list's elements) through

- the system's MessageType the topic carries: a field is held when the type has a Field of its name
  (and, for a nested path, that Field's MessageType holds the rest);
- a ROS 2 type: the same through its ``.msg`` fields, where CKM's names map onto the type's as the
  recorder maps them (as written, else snake_case), a ``stamp``/``frame`` onto its ``header``, and a
  standard type of an interface port holds what :mod:`runtime.ros.interface_types` carries (what it
  drops on purpose, with its reason, is accepted).

Every field not held is refused at the Output's ``topic`` attribute, naming the kind and the port.
``bytes`` topics carry the codec's encoding of any value and are not walked.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from ckmconf.model import BUILTIN_TYPES, Node, Plugin, Profile, Service, SmartResource
from ckmconf.rostypes import is_ros_type

from .checker import Checker
from .interfaces import STANDARD, Port, provided_by, writes_of


def _a(noun: str) -> str:
    return f"{'an' if noun[:1] in 'aeiou' else 'a'} {noun}"


class MessageChecks(Checker):
    """Service Outputs against the fields their kinds write (``self.interfaces`` from :class:`InterfaceChecks`)."""

    interfaces: dict[str, str | None]

    def _output_fields(
        self,
        resource: SmartResource,
        service: Service,
        used: list[Profile],
        kinds: dict[str, tuple[Plugin, type[Any] | None]],
        node: Node | None,
    ) -> None:
        """Each ``<Output>``'s topic type against the fields each of its output plugins writes."""
        ref = f"{resource.name}.{service.name}"
        for out in service.outputs:
            carried = self._topic_type(out.topic, node)
            if carried is None or carried in BUILTIN_TYPES:  # a built-in type: the value-type check says it
                continue
            refused: dict[tuple[str, ...], tuple[list[Plugin], str | None, Port | None]] = {}
            for profile in {p.name: p for p in used}.values():
                plugin, cls = kinds.get(profile.output_plugin(), (None, None))
                if plugin is None or cls is None:
                    continue
                interface, port = self._port(ref, cls, out.name, len(service.outputs))
                written = self._written(cls, out.name, len(service.outputs), interface, port)
                lacking = tuple(self._lacking(carried, written))
                if lacking:  # one problem per Output and missing set, naming every plugin (one per profile)
                    plugins = refused.setdefault(lacking, ([], interface, port))[0]
                    if plugin not in plugins:
                        plugins.append(plugin)
            for lacking, (plugins, interface, port) in refused.items():
                self._refuse(out, ref, plugins, carried, list(lacking), interface, port)

    def _port(self, ref: str, cls: type[Any], output: str, outputs: int) -> tuple[str | None, Port | None]:
        """The interface of the service (or its kind) and the port the Output is, if any."""
        interface = self.interfaces.get(ref) or provided_by(cls)
        if interface is None:
            return None, None
        return interface, STANDARD[interface].port(output, outputs)

    @staticmethod
    def _written(
        cls: type[Any], output: str, outputs: int, interface: str | None, port: Port | None
    ) -> tuple[str, ...]:
        """What the kind writes onto this Output: its own ``WRITES`` entry, else its port's fields. A
        service of one Output publishes the whole result: known only for a kind of one result port."""
        writes = writes_of(cls)
        if outputs > 1:
            return tuple(writes.get(output, port.fields if port is not None else ()))
        ports = {p.name: p.fields for p in STANDARD[interface].outputs} if interface is not None else {}
        entries = {**ports, **writes}
        return tuple(next(iter(entries.values()))) if len(entries) == 1 else ()

    def _lacking(self, carried: str, written: Iterable[str]) -> list[str]:
        """The fields of ``written`` a topic of type ``carried`` does not hold."""
        if is_ros_type(carried):
            ros = self._ros()
            if carried not in ros.ros:
                return []  # an unloadable type is reported at the topic
            return [f for f in written if not self._ros_holds(carried, f)]
        if carried not in self.types:
            return []  # an unknown type is the loader's error
        return [f for f in written if not self._type_holds(carried, f.split("."))]

    def _type_holds(self, type_name: str, parts: list[str], seen: frozenset[str] = frozenset()) -> bool:
        message = self.types.get(type_name)
        if message is None or type_name in seen:
            return False
        name = parts[0].removesuffix("[]")
        field = next((f for f in message.fields if f.name == name), None)
        if field is None:
            return False
        return len(parts) == 1 or self._type_holds(field.type, parts[1:], seen | {type_name})

    def _ros_holds(self, ros_type: str, path: str) -> bool:
        from ..ros.compat import snake_case
        from ..ros.interface_types import holds

        ros = self._ros().ros
        fields: Mapping[str, Any] = dict(ros.fields(ros_type))
        adapted = holds(ros_type, fields, path)
        if adapted is not False:
            return True  # carried by the standard type's adaptation, or dropped on purpose with a reason
        head, _, rest = path.partition(".")
        name = head.removesuffix("[]")
        desc = fields.get(name, fields.get(snake_case(name)))
        if desc is None:
            return False
        if not rest:
            return True
        nested = _nested(desc)
        return nested is not None and nested in ros and self._ros_holds(nested, rest)

    def _refuse(
        self, out: Any, ref: str, plugins: list[Plugin], carried: str, lacking: list[str], interface: str | None,
        port: Port | None,
    ) -> None:
        kind = "ROS type" if is_ros_type(carried) else "MessageType"
        where = f" ({_a(interface)} Output {port.name!r}, docs/interfaces.md)" if interface and port else ""
        advice = (f"; or type the topic {' or '.join(port.messages)}" if port is not None and port.messages
                  and carried not in port.messages else "")
        fix = "name a type that holds them" if is_ros_type(carried) else "add them as <Field>s of the MessageType"
        names = ", ".join(repr(p.name) for p in plugins)
        self.report.error(
            out,
            f"service {ref!r} publishes onto topic {out.topic!r} of {kind} {carried} fields its plugin"
            f"{'s' if len(plugins) > 1 else ''} {names} ({', '.join(dict.fromkeys(p.kind for p in plugins))}) "
            f"write{'' if len(plugins) > 1 else 's'}{where} that the type lacks, so they would be lost: "
            f"{', '.join(lacking)}; {fix}{advice}",
            "topic",
        )


def _nested(desc: Any) -> str | None:
    """The message type a ROS field description names (itself or as elements), if any."""
    from rosbags.interfaces import Nodetype

    kind, detail = desc
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        kind, detail = detail[0]
    return str(detail) if kind == Nodetype.NAME else None
