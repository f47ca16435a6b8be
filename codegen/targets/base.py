"""What an export target provides: :class:`Target` (the registry's entry) and the optional
:class:`BuildVariant` capability.

A target turns a generated observer (its committed design and the C ``uiogen generate`` wrote
from it) into something another tool takes: a folder of C, an FMU, a cross-compiled object. The
required part is small: a ``name`` (``uiogen export --format NAME``), a one-line ``title``, what
``--out`` names (``out``, and the ``suffix`` a file must have) and ``export(config, out, log)``.
A target that also offers a variant of ``uiogen build`` (``--float32``) implements
:class:`BuildVariant`; the command line finds it with ``isinstance`` and names no target.

Nothing outside a target's own folder needs to know which target it handles: the command line
asks the registry (:mod:`codegen.targets`), as it does for families.
"""
from __future__ import annotations

import abc
from pathlib import Path


class Target(abc.ABC):
    """An export target. Register an instance with :func:`codegen.targets.register`."""

    #: ``uiogen export NAME --format ...``
    name: str = ""
    #: what it writes, in one line (``uiogen export --format`` lists it)
    title: str = ""
    #: what ``--out`` names ("FILE.fmu", "DIR")
    out: str = "DIR"
    #: the suffix ``--out`` must have ("" for a folder)
    suffix: str = ""

    @abc.abstractmethod
    def export(self, config, out: Path, log=print) -> Path:
        """Write the target's output of ``config`` (an
        :class:`~codegen.project.observer_file.ObserverConfig` whose generated C is current) to
        ``out``; its path. A user's mistake is a typed :class:`~codegen.errors.UiogenError`."""

    def capabilities(self) -> tuple:
        return tuple(c.__name__ for c in (BuildVariant,) if isinstance(self, c))


class BuildVariant(abc.ABC):
    """A target that is also a variant of ``uiogen build``: ``uiogen build --FLAG [NAME ...]``."""

    #: the option of ``uiogen build`` (without its dashes)
    build_flag: str = ""
    #: its help text
    build_help: str = ""

    @abc.abstractmethod
    def build(self, names, project=None) -> int:
        """Build the variant of the observers ``names`` (all built-in ones when empty); the exit
        status, or a typed error."""


def generated_c(config) -> tuple:
    """(folder, {file name: text}) of the C ``uiogen generate`` wrote for ``config``, checked first:
    generated, its committed design the current one and the C what generate wrote from it (its
    stamp), never as found (an UnknownObserverError naming the command that generates it)."""
    from ..errors import UnknownObserverError
    from ..extension.build import check_generated, generated_dir, require_current
    name = config.name
    folder = generated_dir(config)
    needed = [f"{name}_kernel.c", f"{name}.c", f"{name}_kernel.h", f"{name}.h"]
    missing = [f for f in needed if not (folder / f).is_file()]
    if missing:
        raise UnknownObserverError(f"observer {name!r} has not been generated (no {folder / missing[0]}); "
                                   f"run `uiogen generate {name if config.builtin else config.source}`")
    require_current(config)
    check_generated(config)
    return folder, {f.name: f.read_text() for f in sorted(folder.iterdir()) if f.is_file()}


def write_folder(out, files: dict) -> Path:
    """``files`` ({name: text or bytes}) written into the folder ``out`` (made if missing; an
    OutputError naming a file in the way or what cannot be written), each file atomically."""
    from ..project import outputs
    out = outputs.make_folder(out)
    for name, data in files.items():
        outputs.write_atomic(out / name, data)
    return out
