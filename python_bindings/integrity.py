"""What a compiled extension was built from, checked before it is used (standard library only).

``uiogen build`` records two things the runtime checks at every :func:`python_bindings.load`:

* the SHA-256 of the extension's own bytes, in a sidecar beside it (``_NAME.<abi>.so.sha256``,
  :func:`record_path`): a truncated or overwritten extension is refused before it is loaded (a
  truncated shared object that is loaded dies of SIGBUS, with no message);
* the hashes of the user's files the design was made from -- the observer file, its parameter
  file and its model -- compiled into the extension (its ``SOURCES`` constant,
  :func:`source_digests`): an extension whose observer file, parameters or model changed since it
  was built is refused, naming the file. The observer file is hashed as parsed, less its
  ``[data]`` and ``[precision]`` tables (no design or C derives from them) and its comments, as
  the design's own hash takes it; the parameter file and the model byte for byte.

A source file that is absent is not checked: an extension deployed with its design lock but
without the files it was made from loads (there is nothing to disagree with).
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

RECORD_SUFFIX = ".sha256"
# The roles of the recorded sources, in the order the messages name them.
ROLES = ("observer file", "parameters", "model")


class SourceFileUnreadable(Exception):
    """The observer file is there but cannot be parsed (not UTF-8, not TOML); ``args[0]`` says why."""


def file_sha256(path) -> str:
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


def design_table(raw: bytes) -> dict:
    """An observer file's table as parsed, less ``[data]`` and ``[precision]`` (no design or C
    derives from them): what both the design lock's hash (``codegen.design.lock``) and the
    runtime's source check take of the file.

    Raises
    ------
    SourceFileUnreadable
        The file is not UTF-8 or not TOML.
    """
    import tomllib
    try:
        table = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise SourceFileUnreadable(f"it is not UTF-8 text (byte {exc.start}: {raw[exc.start:exc.start + 1]!r})") \
            from None
    except tomllib.TOMLDecodeError as exc:
        raise SourceFileUnreadable(f"it is not valid TOML ({exc})") from None
    table.pop("data", None)
    table.pop("precision", None)
    return table


def observer_file_sha256(path) -> str:
    """The hash of an observer file's :func:`design_table`.

    Raises
    ------
    SourceFileUnreadable
        The file is not UTF-8 or not TOML.
    """
    with open(path, "rb") as fh:
        table = design_table(fh.read())
    return hashlib.sha256(json.dumps(table, sort_keys=True, default=str).encode()).hexdigest()


def _relative(path, base: Path) -> str:
    try:
        return os.path.relpath(Path(path).resolve(), base.resolve())
    except ValueError:          # another drive
        return str(Path(path).resolve())


def source_digests(observer_file, parameters, model) -> dict:
    """{role: [path relative to the observer file's folder, SHA-256]} of the files a design is
    made from, as ``uiogen build`` compiles them into the extension."""
    base = Path(observer_file).parent
    return {"observer file": [Path(observer_file).name, observer_file_sha256(observer_file)],
            "parameters": [_relative(parameters, base), file_sha256(parameters)],
            "model": [_relative(model, base), file_sha256(model)]}


def changed_sources(recorded: dict, observer_file) -> list:
    """[(role, path)] of the recorded sources that are present and differ from what was built;
    sources that are absent are skipped (module docstring).

    Raises
    ------
    SourceFileUnreadable
        The observer file is there but cannot be parsed; ``args[1]`` is its path.
    """
    observer_file = Path(observer_file)
    base = observer_file.parent
    changed = []
    for role in (r for r in ROLES if r in recorded):
        rel, digest = recorded[role]
        path = observer_file if role == "observer file" else base / rel
        try:
            if role == "observer file":
                try:
                    now = observer_file_sha256(path)
                except SourceFileUnreadable as exc:
                    raise SourceFileUnreadable(exc.args[0], path) from None
            else:
                now = file_sha256(path)
        except FileNotFoundError:
            continue
        if now != digest:
            changed.append((role, path))
    return changed


def record_path(extension: Path) -> Path:
    """The sidecar with the SHA-256 of ``extension``'s bytes (written by ``uiogen build``)."""
    return extension.with_name(extension.name + RECORD_SUFFIX)


def record_text(extension_bytes: bytes, name: str) -> str:
    return f"{hashlib.sha256(extension_bytes).hexdigest()}  {name}\n"


def binary_mismatch(extension: Path) -> str:
    """Why ``extension``'s bytes are not those ``uiogen build`` recorded, or "" when they are."""
    record = record_path(extension)
    try:
        text = record.read_text(encoding="ascii")
    except FileNotFoundError:
        return f"it has no build record {record.name} (built by an older uiogen, or the record was removed)"
    except (OSError, UnicodeDecodeError) as exc:
        return f"its build record {record} is unreadable ({type(exc).__name__})"
    recorded = text.split("  ", 1)[0].strip()
    if file_sha256(extension) != recorded:
        return (f"its bytes are not those its build record {record.name} holds (truncated, or changed after "
                f"`uiogen build`)")
    return ""
