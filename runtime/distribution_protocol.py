"""The configuration distribution wire protocol (§3.1.5.2): what the editor and an agent exchange.

Both sides import it: the agent (:mod:`runtime.distribution`, ``ckm-run --await-config``) and the
editor (:mod:`editor.distribution`). It holds the topics, the bundle hash, the limits and the
check of an incoming push, and nothing that runs a node, so the editor can speak the protocol
without loading the kernel.

Protocol (msgpack maps over the transport; AGENT is the agent's name):

- ``/ckm/agents`` (agent → all, every ``ANNOUNCE_PERIOD`` s and on each change):
  ``{type: "agent", name, host, pid, guid, status, config_hash, node, system, errors, last_id}``
  with status ``waiting`` (nothing pushed yet), ``running``, ``refused`` (the last push was
  refused and nothing runs), ``failed`` (a push was accepted but its node failed to start) or
  ``stopped`` (the agent is leaving).
- ``/ckm/agents/AGENT/config`` (editor → agent): ``{id, node, files: {path: xml}, main}``.
- ``/ckm/agents/AGENT/ack`` (agent → editor): ``{type: "ack", agent, id, accepted, hash,
  node, errors}``. A push resent with the same id is answered again, never applied twice.

``bundle_hash`` is the sha256 of the bundle both sides compute to confirm what runs.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import PurePosixPath
from typing import Any

AGENTS_TOPIC = "/ckm/agents"
ANNOUNCE_PERIOD = 0.5
MAX_BUNDLE = 8 * 1024 * 1024  # bytes of paths and texts together
MAX_FILES = 256
NAME = re.compile(r"[A-Za-z0-9_.-]{1,64}")
_COMPONENT = re.compile(r"[A-Za-z0-9_.+-]{1,128}")


def config_topic(agent: str) -> str:
    """The topic the editor pushes ``agent`` its configurations on."""
    return f"{AGENTS_TOPIC}/{agent}/config"


def ack_topic(agent: str) -> str:
    """The topic ``agent`` acknowledges each push on."""
    return f"{AGENTS_TOPIC}/{agent}/ack"


def bundle_hash(files: Mapping[str, str]) -> str:
    """sha256 over the (path, text) pairs sorted by path, each length-prefixed (UTF-8)."""
    digest = hashlib.sha256()
    for path in sorted(files):
        for part in (path.encode(), files[path].encode()):
            digest.update(len(part).to_bytes(8, "big"))
            digest.update(part)
    return digest.hexdigest()


def bundle_size(files: Mapping[str, str]) -> int:
    """Bytes of the paths and texts together (UTF-8), the figure ``MAX_BUNDLE`` bounds."""
    return sum(len(p.encode()) + len(t.encode()) for p, t in files.items())


class Refused(Exception):
    """A push the agent will not apply; ``errors`` say why."""

    def __init__(self, *errors: str) -> None:
        super().__init__("; ".join(errors))
        self.errors = list(errors)


@dataclass(frozen=True)
class Push:
    """A checked push: the node to run, the bundle (relative path → XML text), its main file and hash."""

    id: str | int
    node: str
    files: dict[str, str]
    main: str
    hash: str


def check_path(path: str) -> None:
    """A bundle path must be relative, plain and stay inside the bundle (hostile input)."""
    parts = PurePosixPath(path).parts
    if not parts or path.startswith("/") or "\\" in path or len(parts) > 16:
        raise Refused(f"bad path {path!r}: paths are relative, '/'-separated, at most 16 deep")
    for part in parts:
        if part in (".", "..") or not _COMPONENT.fullmatch(part):
            raise Refused(f"bad path {path!r}: {part!r} is not a plain file or folder name")
    if not path.endswith(".xml"):
        raise Refused(f"bad path {path!r}: only .xml files are distributed")


def parse_push(message: Any, max_bundle: int = MAX_BUNDLE) -> Push:
    """Check a push message field by field; Refused names the first problem."""
    if not isinstance(message, dict):
        raise Refused(f"a push is a map with id, node, files and main, not {type(message).__name__}")
    ident = message.get("id")
    if isinstance(ident, bool) or not isinstance(ident, (str, int)) or len(str(ident)) > 128:
        raise Refused("the push has no valid id (a string or integer)")
    node, files, main = message.get("node"), message.get("files"), message.get("main")
    if not isinstance(node, str) or not NAME.fullmatch(node):
        raise Refused("the push names no valid node")
    if not isinstance(files, dict) or not files:
        raise Refused("the push has no files (a map of relative path → XML text)")
    if len(files) > MAX_FILES:
        raise Refused(f"the bundle has {len(files)} files; at most {MAX_FILES} are accepted")
    if not all(isinstance(p, str) and isinstance(t, str) for p, t in files.items()):
        raise Refused("the bundle's paths and contents must all be text")
    size = bundle_size(files)
    if size > max_bundle:
        raise Refused(f"the bundle is {size} bytes; at most {max_bundle} are accepted")
    for path in files:
        check_path(path)
    if not isinstance(main, str) or main not in files:
        raise Refused(f"the main file {main!r} is not in the bundle")
    return Push(ident, node, dict(files), main, bundle_hash(files))
