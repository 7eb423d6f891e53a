"""load(): files → schema validation → records → includes merged → semantic checks (§3.1.5.2)."""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, overload

from .binding import Record, bind
from .checks import check_system
from .checks.report import Reporter
from .errors import ConfigError, ConfigErrors, located
from .model.system import Content, Include, Part, System
from .schema import validate
from .source import Limits, SourceFile, local_name, parse_bytes, read_source

_MERGED = [f.name for f in dataclasses.fields(Content) if f.name not in ("loc", "includes")]
_SINGLE = {"network": "Network", "validation": "Validation", "environment": "Environment"}


@dataclass
class LoadResult:
    """What lax loading returns: the system when it could be built, and every problem found."""

    system: System | None
    errors: list[ConfigError] = field(default_factory=list)
    files: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True if no problem was found."""
        return not self.errors


@overload
def load(path: str | os.PathLike[str], *, strict: Literal[True] = ..., limits: Limits = ...) -> System: ...
@overload
def load(path: str | os.PathLike[str], *, strict: Literal[False], limits: Limits = ...) -> LoadResult: ...


def load(path: str | os.PathLike[str], *, strict: bool = True, limits: Limits = Limits()) -> System | LoadResult:
    """Load a System (or a Part with what it includes) and check it.

    Strict mode raises the first ConfigError (by file and position); lax mode returns a
    LoadResult with all of them, which is what the editor shows.
    """
    result = _Loader(limits).run(os.fspath(path), None)
    return _finish(result, strict)


@overload
def load_bytes(
    data: bytes, path: str, *, strict: Literal[True] = ..., limits: Limits = ..., includes: bool = ...
) -> System: ...
@overload
def load_bytes(
    data: bytes, path: str, *, strict: Literal[False], limits: Limits = ..., includes: bool = ...
) -> LoadResult: ...


def load_bytes(
    data: bytes, path: str, *, strict: bool = True, limits: Limits = Limits(), includes: bool = True
) -> System | LoadResult:
    """Like load(), for text already in memory (the editor, configurations sent over the network).

    ``path`` names the text in messages and anchors relative includes; ``includes=False`` refuses
    every ``<Include>`` (text from another process must not make this one read its files).
    """
    result = _Loader(limits, includes).run(path, data)
    return _finish(result, strict)


def _finish(result: LoadResult, strict: bool) -> System | LoadResult:
    if not strict:
        return result
    if result.errors:
        raise result.errors[0]
    assert result.system is not None
    return result.system


def read_document(path: str | os.PathLike[str], *, limits: Limits = Limits()) -> System | Part:
    """One file as written, includes not followed: the unit the editor opens and saves."""
    source = read_source(os.fspath(path), limits)
    errors = validate(source)
    if errors:
        raise ConfigErrors(errors)
    return _bind_root(source)


def _bind_root(source: SourceFile) -> System | Part:
    cls: type[System] | type[Part] = System if local_name(source.root.tag) == "System" else Part
    return bind(cls, source.root, source)


class _Loader:
    def __init__(self, limits: Limits, includes: bool = True) -> None:
        self.limits = limits
        self.includes = includes
        self.sources: dict[str, SourceFile] = {}
        self.documents: list[System | Part] = []
        self.errors: list[ConfigError] = []

    def run(self, path: str, data: bytes | None) -> LoadResult:
        root = self._read(path, data, stack=[], via=[])
        files = list(self.sources)
        if root is None or self.errors:
            return LoadResult(None, sorted(self.errors, key=ConfigError.sort_key), files)
        system = self._merge(root)
        reporter = Reporter(self.sources)
        check_system(system, reporter)
        self.errors.extend(reporter.errors)
        errors = sorted(set(self.errors), key=ConfigError.sort_key)
        return LoadResult(None if errors else system, errors, files)

    def _read(self, path: str, data: bytes | None, stack: list[str], via: list[Include]) -> System | Part | None:
        """Read one file; ``stack`` holds the files being read and ``via`` the Include followed in each."""
        key = os.path.realpath(path)
        include = via[-1] if via else None
        try:
            source = parse_bytes(path, data, self.limits) if data is not None else read_source(path, self.limits)
        except ConfigError as error:
            self.errors.append(self._at_include(include, error) if include is not None else error)
            return None
        self.sources[path] = source
        schema_errors = validate(source)
        if schema_errors:
            self.errors.extend(schema_errors)
            return None
        document = _bind_root(source)
        if include is not None and isinstance(document, System):
            self.errors.append(ConfigError.of(include, f"{include.href} holds a System; only a Part can be included"))
            return None
        if not self.includes and document.includes:
            message = "cannot include {}: text received from another process includes no file"
            self.errors.extend(
                ConfigError.at(source.attr_loc_at(located(i), "href"), message.format(i.href))
                for i in document.includes
            )
            return None
        self.documents.append(document)
        base = Path(path).parent
        for inc in document.includes:
            self._include(base, [*stack, key], [*via, inc])
        return document

    def _include(self, base: Path, stack: list[str], via: list[Include]) -> None:
        include = via[-1]
        if os.path.isabs(include.href) or include.href.startswith("~"):
            self.errors.append(
                ConfigError.of(include, f"include paths are relative to the including file: {include.href}")
            )
            return
        if not include.href.endswith(".xml"):
            self.errors.append(ConfigError.of(include, f"only .xml files can be included: {include.href}"))
            return
        target = os.path.normpath(base / include.href)
        key = os.path.realpath(target)
        if key in stack:
            start = stack.index(key)  # reported where the cycle begins: in the file that was asked for
            chain = " → ".join(Path(p).name for p in [*stack[start:], key])
            self.errors.append(ConfigError.of(via[start], f"include cycle: {chain}"))
            return
        if any(os.path.realpath(p) == key for p in self.sources):
            return  # read once, like a header guard
        if len(self.sources) >= self.limits.max_files:
            self.errors.append(ConfigError.of(include, f"more than {self.limits.max_files} files included"))
            return
        self._read(target, None, stack, via)

    def _at_include(self, include: Include, error: ConfigError) -> ConfigError:
        if error.message in ("file not found", "not a regular file") or error.message.startswith("cannot read"):
            return ConfigError.of(include, f"cannot include {include.href}: {error.message}")
        return error

    def _merge(self, root: System | Part) -> System:
        # Included parts come first, like text pulled in at the top of the including file.
        ordered = [d for d in self.documents if d is not root] + [root]
        merged: dict[str, object] = {}
        seen: dict[str, Record] = {}
        for name in _MERGED:
            if name in _SINGLE:
                for document in ordered:
                    value = getattr(document, name)
                    if value is None:
                        continue
                    if name in seen:
                        self.errors.append(_duplicate(value, _SINGLE[name], seen[name]))
                        continue
                    seen[name] = value
                    merged[name] = value
            else:
                merged[name] = tuple(item for document in ordered for item in getattr(document, name))
        if isinstance(root, System):
            return System(name=root.name, version=root.version, description=root.description, loc=root.loc, **merged)  # type: ignore[arg-type]
        stem = Path(root.loc.file).stem if root.loc else "part"
        return System(name=stem, version=root.version, description=root.description, loc=root.loc, **merged)  # type: ignore[arg-type]


def _duplicate(record: Record, kind: str, first: Record) -> ConfigError:
    where = f"{first.loc.file}:{first.loc.line}" if first.loc else "another file"
    return ConfigError.of(record, f"{kind} is defined twice (first at {where})")
