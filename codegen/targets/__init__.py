"""Export targets: one folder each, one registry.

Each target lives in ``codegen/targets/NAME/`` with an ``__init__.py`` defining ``TARGET``, an
instance of :class:`~codegen.targets.base.Target` (templates and vendor headers beside it). The
command line asks this registry, never names a target: ``uiogen export NAME --format TARGET``
runs ``get(TARGET).export(...)``, ``uiogen export --format`` lists :func:`names`, and ``uiogen
build --FLAG`` runs a target with the :class:`~codegen.targets.base.BuildVariant` capability.

>>> from codegen import targets
>>> targets.get("fmu").suffix
'.fmu'

A new target is one folder and one line in :data:`BUILTIN` (or, from outside the package,
``targets.register(MyTarget())``); see ``README.md`` here. Shared by the FMI targets:
:mod:`.fmi`.
"""
from __future__ import annotations

from ..errors import UnsupportedError
from ..plugins import Registry
from .base import BuildVariant, Target

__all__ = ["Target", "BuildVariant", "BUILTIN", "register", "unregister", "get", "names", "all_targets"]

#: the targets that ship with uiogen, imported on first use (each module defines ``TARGET``)
BUILTIN = ("c", "fmu", "fmu3", "float32", "cortexm", "misra")

TARGETS = Registry("target", Target, __name__, "TARGET", required=("name", "title"),
                   unknown=lambda name, known: UnsupportedError(f"unknown export target {name!r}; known: "
                                                                f"{', '.join(known)}"))
"""Every target ``uiogen export --format`` takes."""

register, unregister, get, names, all_targets = (TARGETS.register, TARGETS.unregister, TARGETS.get, TARGETS.names,
                                                 TARGETS.entries)
