"""What a compiled extension was built from, checked before it is used (standard library only).

``uiogen build`` records two things the runtime checks at every :func:`python_bindings.load`:

* the SHA-256 of the extension's own bytes, in a sidecar beside it (``_NAME.<abi>.so.sha256``,
  :func:`record_path`): a truncated or overwritten extension is refused before it is loaded (a
  truncated shared object that is loaded dies of SIGBUS, with no message);
* the hashes of the user's files the design was made from -- the observer file, its parameter
  file, its model and the modules beside the model that it imports --
  compiled into the extension (its ``SOURCES`` constant,
  :func:`source_digests`): an extension whose observer file, parameters or model changed since it
  was built is refused, naming the file. Each file is hashed for what it says, not how it is
  written (:data:`HASHING`), by the same functions the design lock's hash calls
  (``codegen.design.lock.design_inputs``), so ``load`` and ``uiogen generate`` always agree on
  whether a file changed: the observer file as parsed, less its ``[data]`` and ``[precision]``
  tables (no design or C derives from them); the parameter file as parsed (TOML); the model as
  its syntax tree (:func:`python_meaning`). An edit of comments, blank lines, spacing or
  indentation changes none of them; any edit of a value, a key or the code does.

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
# The modules beside a user's model that it imports, each hashed byte for byte (as the design lock does).
HELPERS = "model helpers"
# How the recorded sources are hashed (the record's "hashing" entry): 2, each file for what it says
# (module docstring). A record without the entry (an extension built before) hashed the parameter
# file and the model byte for byte, and is checked by that rule.
HASHING = 2


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
        table = tomllib.loads(raw.decode("utf-8-sig"))
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


def parameters_sha256(path) -> str:
    """The hash of a parameter file as parsed (TOML): its comments and layout are not hashed, nor its
    ``[sensor_noise]`` table (the sensors' noise levels ``uiogen validate`` adds: no design or C derives
    from them, so declaring or editing them re-solves nothing). A file that is not UTF-8 TOML (it
    cannot be designed from) is hashed byte for byte."""
    import tomllib
    with open(path, "rb") as fh:
        raw = fh.read()
    try:
        data = tomllib.loads(raw.decode("utf-8-sig"))
        data.pop("sensor_noise", None)
        text = json.dumps(data, sort_keys=True, default=str)
    except (UnicodeDecodeError, tomllib.TOMLDecodeError):
        return hashlib.sha256(b"bytes\0" + raw).hexdigest()
    return hashlib.sha256(b"toml\0" + text.encode()).hexdigest()


def python_meaning(raw: bytes) -> str:
    """A Python source's syntax tree as text: its names, numbers, strings (docstrings included)
    and structure, without its comments, blank lines, spacing or indentation width. The same on
    every Python version the project supports: fields that are None or empty are left out (a
    version that adds a field, as 3.12's ``type_params``, gives it such a default), and positions
    are not written (``ast.dump`` writes the fields of the running version, and 3.13 changed what
    it leaves out).

    Raises
    ------
    SyntaxError, ValueError, RecursionError
        ``raw`` is not Python source that parses.
    """
    import ast

    def dump(node) -> str:
        if isinstance(node, ast.AST):
            fields = [f"{f}={dump(v)}" for f in node._fields
                      for v in [getattr(node, f, None)] if v is not None and v != []]
            return f"{type(node).__name__}({', '.join(fields)})"
        if isinstance(node, list):
            return f"[{', '.join(dump(v) for v in node)}]"
        return repr(node)
    return dump(ast.parse(raw))


def model_sha256(path) -> str:
    """The hash of a model file's :func:`python_meaning`; a file that does not parse (it cannot be
    imported) is hashed byte for byte."""
    with open(path, "rb") as fh:
        raw = fh.read()
    try:
        text = python_meaning(raw)
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return hashlib.sha256(b"bytes\0" + raw).hexdigest()
    return hashlib.sha256(b"python\0" + text.encode()).hexdigest()


def _relative(path, base: Path) -> str:
    try:
        return os.path.relpath(Path(path).resolve(), base.resolve())
    except ValueError:          # another drive
        return str(Path(path).resolve())


def source_digests(observer_file, parameters, model, helpers=()) -> dict:
    """{role: [path relative to the observer file's folder, SHA-256]} of the files a design is
    made from, as ``uiogen build`` compiles them into the extension; ``helpers``: the modules beside
    a user's model that it imports (``model helpers``: [[path, SHA-256 of the bytes], ...])."""
    base = Path(observer_file).parent
    out = {"observer file": [Path(observer_file).name, observer_file_sha256(observer_file)],
           "parameters": [_relative(parameters, base), parameters_sha256(parameters)],
           "model": [_relative(model, base), model_sha256(model)], "hashing": HASHING}
    if helpers:
        out[HELPERS] = [[_relative(h, base), file_sha256(h)] for h in helpers]
    return out


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
    hashing = recorded.get("hashing", 1)
    if hashing not in (1, HASHING):
        raise ValueError(f"hashing rule {hashing!r}")       # a newer uiogen's record: the caller refuses it
    hashes = ({"parameters": parameters_sha256, "model": model_sha256} if hashing == HASHING
              else {"parameters": file_sha256, "model": file_sha256})
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
                now = hashes[role](path)
        except FileNotFoundError:
            continue
        if now != digest:
            changed.append((role, path))
    for rel, digest in recorded.get(HELPERS, ()):
        try:
            if file_sha256(base / rel) != digest:
                changed.append(("model helper", base / rel))
        except FileNotFoundError:
            continue
    return changed


def record_path(extension: Path) -> Path:
    """The sidecar with the SHA-256 of ``extension``'s bytes (written by ``uiogen build``)."""
    return extension.with_name(extension.name + RECORD_SUFFIX)


def record_text(extension_bytes: bytes, name: str) -> str:
    return f"{hashlib.sha256(extension_bytes).hexdigest()}  {name}\n"


def binary_mismatch(extension: Path, copy: Path | None = None) -> str:
    """Why ``extension``'s bytes (or those of ``copy``, a copy of it) are not those ``uiogen build``
    recorded, or "" when they are."""
    record = record_path(extension)
    try:
        text = record.read_text(encoding="ascii")
    except FileNotFoundError:
        return f"it has no build record {record.name} (built by an older uiogen, or the record was removed)"
    except (OSError, UnicodeDecodeError) as exc:
        return f"its build record {record} is unreadable ({type(exc).__name__})"
    recorded = text.split("  ", 1)[0].strip()
    if file_sha256(copy or extension) != recorded:
        return (f"its bytes are not those its build record {record.name} holds (truncated, or changed after "
                f"`uiogen build`)")
    return ""


def elf_truncation(path: Path) -> str:
    """Why the ELF shared object ``path`` cannot be whole, or "" when its headers fit in the file.

    dlopen maps the segments a program header names; one that ends past the end of the file is a
    SIGBUS at the first touch, not an error. The build record cannot catch a file truncated and
    re-recorded, so the structure is checked too: the program and section header tables and every
    loadable segment must lie inside the file. A file that is not ELF (another platform) is not
    checked here."""
    import struct
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            head = fh.read(64)
            if head[:4] != b"\x7fELF":
                return ""
            if len(head) < 52 or head[4] not in (1, 2) or head[5] not in (1, 2):
                return "its ELF header is cut short or malformed"
            end = "<" if head[5] == 1 else ">"
            if head[4] == 2:            # 64-bit
                if len(head) < 64:
                    return "its ELF header is cut short"
                phoff, shoff = struct.unpack(end + "QQ", head[32:48])
                phentsize, phnum, shentsize, shnum = struct.unpack(end + "HHHH", head[54:62])
                segment, fields = 56, end + "IIQQQQQQ"
            else:
                phoff, shoff = struct.unpack(end + "II", head[28:36])
                phentsize, phnum, shentsize, shnum = struct.unpack(end + "HHHH", head[42:50])
                segment, fields = 32, end + "IIIIIIII"
            for what, offset, count, entry in (("program header table", phoff, phnum, phentsize),
                                                ("section header table", shoff, shnum, shentsize)):
                if count and offset + count * entry > size:
                    return f"its {what} ends at byte {offset + count * entry}, past its end ({size} bytes): truncated"
            if phentsize < segment:
                return "its program headers are malformed"
            fh.seek(phoff)
            table = fh.read(phnum * phentsize)
    except OSError as exc:
        return f"it is unreadable ({type(exc).__name__})"
    for k in range(phnum):
        values = struct.unpack(fields, table[k * phentsize:k * phentsize + segment])
        # 64-bit: type, flags, offset, vaddr, paddr, filesz, memsz, align; 32-bit: type, offset, vaddr,
        # paddr, filesz, memsz, flags, align
        kind, offset, filesz = (values[0], values[2], values[5]) if segment == 56 else (values[0], values[1], values[4])
        if kind == 1 and offset + filesz > size:          # PT_LOAD
            return f"its loadable segment {k} ends at byte {offset + filesz}, past its end ({size} bytes): truncated"
    return ""

