"""What a user's model file reads while it is imported, so that a design never depends on a file its
stamp does not see.

A design is stamped with the files it derives from (:mod:`codegen.design.sources`): the model, the
modules beside it that it imports (``from tyre_data import C_SCALE``: followed in the source, hashed
byte for byte) and the parameter file. A model that reads anything else -- a JSON or CSV file with
tyre data, a module imported from some other folder by path -- would leave the design, the C and
the extension current after that file changed. So :func:`watching` records, with an audit hook
(:func:`sys.addaudithook`, on the importing thread only), every file opened while the model runs
(SQLite databases too, which are opened in C) and every child process it starts (whose reads no hook
of this process sees), and :func:`check` refuses the model when it started a process, or when a file
it read is neither installed code (the standard library, site-packages) nor in the stamp: numbers
belong in the parameter file, or in a Python module beside the model; a model file built on another
one names it (``BASE_MODEL = "../model.py"``, :data:`codegen.design.sources.BASE_MODEL`).

The model's folder is on ``sys.path`` while it is imported, so that the modules beside it import
whatever the current directory.
"""
from __future__ import annotations

import contextlib
import importlib.machinery
import os
import site
import sys
import sysconfig
import threading
from pathlib import Path

from ..errors import ModelDefinitionError

_state = threading.local()
_installed = False
_CODE = tuple(importlib.machinery.all_suffixes()) + (".pyc",)


# the audit events of a child process (whose reads no audit hook of this process sees)
_PROCESS_EVENTS = frozenset({"subprocess.Popen", "os.system", "os.exec", "os.posix_spawn", "os.spawn", "os.fork",
                             "os.forkpty", "pty.spawn"})


def _hook(event: str, args) -> None:
    reads = getattr(_state, "reads", None)
    if reads is None or not args and event != "os.fork":
        return
    if event == "sqlite3.connect":                       # SQLite opens its database in C, past the "open" event
        if isinstance(args[0], (str, bytes, os.PathLike)) and os.fsdecode(args[0]) not in ("", ":memory:"):
            reads.append(os.fsdecode(args[0]))
        return
    if event in _PROCESS_EVENTS:
        reads.append(Process(event, args))
        return
    if event != "open":
        return
    path, mode = args[0], args[1] if len(args) > 1 else None
    flags = args[2] if len(args) > 2 else 0
    if isinstance(path, int):
        return
    writing = (any(c in mode for c in "wax") and "+" not in mode) if isinstance(mode, str) else \
        (mode is None and isinstance(flags, int) and (flags & os.O_ACCMODE) == os.O_WRONLY)
    if not writing:
        reads.append(os.fsdecode(path))


class Process(tuple):
    """A child process the model started while imported (its audit event and arguments)."""

    def __new__(cls, event, args):
        return super().__new__(cls, (event, args))

    def command(self) -> str:
        event, args = self
        if event == "os.system" and args:
            return os.fsdecode(args[0]) if isinstance(args[0], (str, bytes)) else repr(args[0])
        if event == "os.fork" or len(args) < 2:
            return event
        argv = args[1]
        if isinstance(argv, (str, bytes)):
            return os.fsdecode(argv)
        try:
            return " ".join(os.fsdecode(a) if isinstance(a, (str, bytes, os.PathLike)) else str(a) for a in argv)
        except TypeError:
            return repr(argv)


@contextlib.contextmanager
def watching(path):
    """Record the files opened on this thread while the block runs (the model file's import), with
    the model's folder first on ``sys.path``. A model loaded while another is (the file ``uiogen new
    --from-model --outputs`` writes loads the user's model) is read for both: what it reads counts for
    the outer model too, whose stamp must then hold it (:data:`codegen.design.sources.BASE_MODEL`)."""
    global _installed
    if not _installed:
        sys.addaudithook(_hook)          # cannot be removed: it records only inside this block
        _installed = True
    folder = str(Path(path).resolve().parent)
    reads, outer = [], getattr(_state, "reads", None)
    _state.reads = reads
    sys.path.insert(0, folder)
    try:
        yield reads
    finally:
        _state.reads = outer
        if outer is not None:
            outer.extend(reads)
        with contextlib.suppress(ValueError):
            sys.path.remove(folder)


def replay(reads) -> None:
    """Count ``reads`` (what a model module read when it was imported) for the model being imported now,
    which loads that module again from this process's modules: the same files, read once."""
    current = getattr(_state, "reads", None)
    if current is not None:
        current.extend(reads)


@contextlib.contextmanager
def unwatched():
    """Nothing recorded while the block runs: the toolchain's own reads after a model's import (its
    checks parse the model's sources) are not the model's."""
    outer = getattr(_state, "reads", None)
    _state.reads = None
    try:
        yield
    finally:
        _state.reads = outer


def _installed_prefixes() -> list:
    paths = {sys.prefix, sys.base_prefix, sys.exec_prefix, sys.base_exec_prefix,
             *(sysconfig.get_paths().values()), "/dev", "/proc", "/sys"}
    with contextlib.suppress(AttributeError):
        paths.update(site.getsitepackages())
    with contextlib.suppress(AttributeError):
        paths.add(site.getusersitepackages())
    return [Path(p).resolve() for p in paths if p]


def check(path, reads) -> None:
    """Refuse the model at ``path`` when it read a file its stamp does not cover (module docstring).

    Raises
    ------
    ModelDefinitionError
        naming the model file, the file it read and what to do instead.
    """
    from ..design.sources import BASE_MODEL, ROOT, user_closure
    stamped = set(user_closure(path))
    prefixes = _installed_prefixes()
    for raw in reads:
        if isinstance(raw, Process):
            raise ModelDefinitionError(
                f"{path}: the model starts a process ({raw.command()[:200]}) while it is imported, whose reads and "
                f"output no design stamp covers (after a change of what it reads the design, the C and the extension "
                f"would stay 'current'); put the numbers in the parameter file, or in a Python module beside the "
                f"model that it imports by name (stamped)")
        f = Path(raw) if os.path.isabs(raw) else Path.cwd() / raw
        try:
            f = f.resolve()
        except OSError:
            continue
        if f in stamped or "__pycache__" in f.parts or f.is_dir():
            continue
        code = f.suffix in _CODE
        if code and (f.is_relative_to(ROOT) or any(f.is_relative_to(p) for p in prefixes)):
            continue                                  # installed code, or the toolchain's (stamped)
        if not code and any(f.is_relative_to(p) for p in prefixes):
            continue                                  # a library's own data (its version is pinned)
        what = ("imports the module" if code else "reads the file")
        raise ModelDefinitionError(
            f"{path}: the model {what} {f} while it is imported, which no design stamp covers (after an edit "
            f"of it the design, the C and the extension would stay 'current'); put the numbers in the parameter "
            f"file, or in a Python module beside the model that it imports by name (stamped)"
            + (f"; a model file built on another names it: {BASE_MODEL} = \"PATH\" (stamped)" if code else ""))
