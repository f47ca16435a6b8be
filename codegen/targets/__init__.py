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

import importlib

from ..errors import UnsupportedError
from .base import BuildVariant, Target

__all__ = ["Target", "BuildVariant", "BUILTIN", "register", "unregister", "get", "names", "all_targets"]

#: the targets that ship with uiogen, imported on first use (each module defines ``TARGET``)
BUILTIN = ("c", "fmu", "fmu3", "float32", "cortexm", "misra")

_REGISTRY: dict = {}
_LOADED = False


def _load_builtin() -> None:
    global _LOADED
    if not _LOADED:
        _LOADED = True
        for name in BUILTIN:
            register(importlib.import_module(f"{__name__}.{name}").TARGET)


def register(target: Target, replace: bool = False) -> Target:
    """Make ``target`` available to ``uiogen export --format target.name``."""
    _load_builtin()
    if not isinstance(target, Target):
        raise TypeError(f"register() takes a codegen.targets.Target, got {type(target).__name__}")
    if not target.name or not target.title:
        raise TypeError(f"{type(target).__name__}: a target needs a name and a title")
    if target.name in _REGISTRY and not replace and _REGISTRY[target.name] is not target:
        raise ValueError(f"a target named {target.name!r} is registered already (replace=True to override)")
    _REGISTRY[target.name] = target
    return target


def unregister(name: str) -> None:
    _REGISTRY.pop(name, None)


def get(name: str) -> Target:
    _load_builtin()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise UnsupportedError(f"unknown export target {name!r}; known: {', '.join(names())}") from None


def names() -> tuple:
    _load_builtin()
    return tuple(_REGISTRY)


def all_targets() -> tuple:
    _load_builtin()
    return tuple(_REGISTRY.values())
