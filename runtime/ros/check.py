"""A run's rosbag2 bags read back by readers that are not CKM's (issue L point 2, thesis §4.4.1).

``ckm-bag check RUN_DIR`` (:mod:`runtime.ros.bag_cli`) finds every bag of a run (a folder holding
``metadata.yaml``: ``RUN_DIR/bag``, ``RUN_DIR/bag-NODE`` …, or a bag directory itself) and checks,
per bag:

- ``metadata.yaml``: rosbag2 format **version 9**, a storage ``mcap`` or ``sqlite3``, every topic in
  ``cdr`` serialisation with a ROS type and a ``RIHS01_`` type hash, the storage files it names present;
- an **MCAP** file, with the ``mcap`` reader and the ``mcap-ros2-support`` decoder: the header's
  profile ``ros2``, every schema in ``ros2msg`` encoding, every channel in ``cdr``, and **every
  message decoded**;
- a **sqlite3** file, with ``rosbags``' reader: every connection in ``cdr`` with a ``.msg``
  (``ros2msg``) definition, and every message deserialised by a ``rosbags`` type store that starts
  from the standard Jazzy types and learns the others from the definitions in the bag;
- in both, the messages decoded per topic against the counts ``metadata.yaml`` announces.

Nothing here uses :mod:`runtime.ros.bag` or the CKM type store: a bag that passes is readable by
the tools ROS 2 users have (Foxglove reads MCAP through the same schemas, ``ros2 bag`` both).
"""

from __future__ import annotations

import sqlite3
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ruamel.yaml import YAML

BAG_VERSION = 9
STORAGES = ("mcap", "sqlite3")


@dataclass
class BagCheck:
    """What :func:`check_bag` found in one bag: counts per topic, and every problem met."""

    path: Path
    storage: str = ""
    version: int | None = None
    topics: dict[str, str] = field(default_factory=dict)  # topic → ROS type (metadata.yaml)
    announced: Counter[str] = field(default_factory=Counter)  # messages per topic (metadata.yaml)
    decoded: Counter[str] = field(default_factory=Counter)  # messages per topic the readers decoded
    readers: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when the bag has no problem and every announced message was decoded."""
        return not self.problems

    def to_dict(self) -> dict[str, Any]:
        """The result as plain data (``ckm-bag check --json``)."""
        return {
            "bag": str(self.path),
            "storage": self.storage,
            "version": self.version,
            "readers": self.readers,
            "topics": {
                t: {"type": ros_type, "announced": self.announced[t], "decoded": self.decoded[t]}
                for t, ros_type in sorted(self.topics.items())
            },
            "messages": sum(self.decoded.values()),
            "problems": self.problems,
            "ok": self.ok,
        }


def find_bags(run_dir: Path) -> list[Path]:
    """The bags of a run: ``run_dir`` itself when it is one, else every folder up to two levels below
    it holding a ``metadata.yaml`` (``RUN_DIR/bag``, ``RUN_DIR/bag-NODE``, ``RUN_DIR/run/bag`` …)."""
    if (run_dir / "metadata.yaml").is_file():
        return [run_dir]
    found: list[Path] = []
    for child in sorted(p for p in run_dir.iterdir() if p.is_dir()):
        if (child / "metadata.yaml").is_file():
            found.append(child)
            continue
        found += [g for g in sorted(child.iterdir()) if g.is_dir() and (g / "metadata.yaml").is_file()]
    return found


def check_bag(path: Path) -> BagCheck:
    """Check one bag directory with the independent readers (see the module docstring)."""
    result = BagCheck(path)
    info = _metadata(path, result)
    if info is None:
        return result
    files = [path / str(name) for name in info.get("relative_file_paths") or []]
    missing = [str(f) for f in files if not f.is_file()]
    if missing:
        result.problems.append(f"{path}: metadata.yaml names storage files that are not there: {', '.join(missing)}")
        return result
    if not files:
        result.problems.append(f"{path}: metadata.yaml names no storage file")
    for storage_file in files:
        try:
            if result.storage == "mcap":
                _read_mcap(storage_file, result)
            elif result.storage == "sqlite3":
                _read_sqlite3(path, storage_file, result)
        except Exception as error:  # a reader that cannot go on: the file itself is broken
            result.problems.append(f"{storage_file}: {type(error).__name__}: {error}")
    for topic in sorted(set(result.announced) | set(result.decoded)):
        if result.announced[topic] != result.decoded[topic]:
            result.problems.append(
                f"{path}: {topic}: metadata.yaml announces {result.announced[topic]} messages, "
                f"{result.decoded[topic]} were decoded"
            )
    return result


def check_run(run_dir: Path) -> list[BagCheck]:
    """Check every bag of a run directory (:func:`find_bags`); FileNotFoundError when it has none."""
    if not run_dir.is_dir():
        raise FileNotFoundError(f"{run_dir}: no such directory")
    bags = find_bags(run_dir)
    if not bags:
        raise FileNotFoundError(f"{run_dir}: no rosbag2 bag (a folder with metadata.yaml) here or below")
    return [check_bag(bag) for bag in bags]


# ---------------------------------------------------------------------- metadata.yaml


def _metadata(path: Path, result: BagCheck) -> dict[str, Any] | None:
    """The ``rosbag2_bagfile_information`` of the bag, its topics and counts noted in ``result``."""
    try:
        document = YAML(typ="safe", pure=True).load((path / "metadata.yaml").read_text(encoding="utf-8"))
    except Exception as error:
        result.problems.append(f"{path}/metadata.yaml: cannot be read: {type(error).__name__}: {error}")
        return None
    info = document.get("rosbag2_bagfile_information") if isinstance(document, dict) else None
    if not isinstance(info, dict):
        result.problems.append(f"{path}/metadata.yaml: no rosbag2_bagfile_information")
        return None
    result.version = info.get("version")
    if result.version != BAG_VERSION:
        result.problems.append(f"{path}/metadata.yaml: version {result.version!r}, expected {BAG_VERSION}")
    result.storage = str(info.get("storage_identifier", ""))
    if result.storage not in STORAGES:
        result.problems.append(f"{path}/metadata.yaml: storage {result.storage!r}, expected one of {STORAGES}")
    for entry in info.get("topics_with_message_count") or []:
        meta = entry.get("topic_metadata") or {}
        name, ros_type = str(meta.get("name")), str(meta.get("type"))
        result.topics[name] = ros_type
        result.announced[name] += int(entry.get("message_count") or 0)
        where = f"{path}/metadata.yaml: {name}"
        if meta.get("serialization_format") != "cdr":
            result.problems.append(f"{where}: serialization_format {meta.get('serialization_format')!r}, not cdr")
        if not str(meta.get("type_description_hash", "")).startswith("RIHS01_"):
            result.problems.append(f"{where}: no RIHS01 type_description_hash")
    total = info.get("message_count")
    if total != sum(result.announced.values()):
        result.problems.append(
            f"{path}/metadata.yaml: message_count {total!r}, its topics add up to {sum(result.announced.values())}"
        )
    return info


# ---------------------------------------------------------------------- MCAP: mcap + mcap-ros2-support


def _read_mcap(storage_file: Path, result: BagCheck) -> None:
    """Every message of an MCAP file decoded by ``mcap_ros2``; profile, schema and message encodings."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    result.readers.append("mcap + mcap-ros2-support")
    with storage_file.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        profile = reader.get_header().profile
        if profile != "ros2":
            result.problems.append(f"{storage_file}: profile {profile!r}, not ros2")
        summary = reader.get_summary()
        if summary is None:
            result.problems.append(f"{storage_file}: no summary section (the file was not finished)")
        else:
            for known in summary.schemas.values():
                if known.encoding != "ros2msg":
                    result.problems.append(f"{storage_file}: schema {known.name} in {known.encoding!r}, not ros2msg")
            for channel in summary.channels.values():
                if channel.message_encoding != "cdr":
                    result.problems.append(
                        f"{storage_file}: channel {channel.topic} in {channel.message_encoding!r}, not cdr"
                    )
                expected = result.topics.get(channel.topic)
                schema = summary.schemas.get(channel.schema_id)
                if expected is not None and schema is not None and schema.name != expected:
                    result.problems.append(
                        f"{storage_file}: channel {channel.topic} has schema {schema.name}, "
                        f"metadata.yaml says {expected}"
                    )
        for _schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            if decoded is None:
                result.problems.append(f"{storage_file}: {channel.topic} at {message.log_time} ns: not decoded")
                continue
            result.decoded[channel.topic] += 1


# ---------------------------------------------------------------------- sqlite3: rosbags


def _read_sqlite3(bag: Path, storage_file: Path, result: BagCheck) -> None:
    """Every message of a sqlite3 bag deserialised through ``rosbags``' reader and type store."""
    from rosbags.interfaces import MessageDefinitionFormat
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    result.readers.append("rosbags")
    with sqlite3.connect(f"file:{storage_file}?mode=ro", uri=True) as db:  # the schema rosbag2 writes
        tables = {name for (name,) in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    for table in ("topics", "messages", "message_definitions"):
        if table not in tables:
            result.problems.append(f"{storage_file}: no table {table!r}")
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        for connection in reader.connections:
            where = f"{storage_file}: {connection.topic}"
            serialization = getattr(connection.ext, "serialization_format", None)  # rosbag1 has none
            if serialization != "cdr":
                result.problems.append(f"{where}: serialization {serialization!r}, not cdr")
            definition = connection.msgdef
            if definition.format != MessageDefinitionFormat.MSG or not definition.data:
                result.problems.append(f"{where}: no ros2msg definition of {connection.msgtype}")
            elif connection.msgtype not in store.fielddefs:
                store.register(get_types_from_msg(definition.data, connection.msgtype))
        for connection, timestamp, data in reader.messages():
            try:
                message = store.deserialize_cdr(data, connection.msgtype)
            except Exception as error:
                result.problems.append(f"{storage_file}: {connection.topic} at {timestamp} ns: {error}")
                continue
            if getattr(message, "__msgtype__", None) != connection.msgtype:
                where = f"{storage_file}: {connection.topic} at {timestamp} ns"
                result.problems.append(f"{where}: not a {connection.msgtype}")
                continue
            result.decoded[connection.topic] += 1
