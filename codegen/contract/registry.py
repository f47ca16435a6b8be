"""The registry of observer families: the one place a family's name (an observer file's ``family = "..."``)
becomes the family.

The observer-file reader (:mod:`codegen.project.observer_file`) asks it once per file and hands the family
down on the configuration (``ObserverConfig.observer_family``); the stages below never look a family up.
The families that ship with uiogen are the packages ``codegen.families.NAME`` that ``codegen.families.BUILTIN``
lists, imported on first use as plug-ins are (by the module's name: nothing here imports a family); each
defines ``FAMILY``, an instance of :class:`~codegen.contract.family.Family`.
"""
from __future__ import annotations

import importlib

from ..errors import UnknownFamilyError
from .family import Family

#: the package of the families that ship with uiogen (its ``BUILTIN`` names them)
PACKAGE = "codegen.families"

_REGISTRY: dict = {}
_LOADED = False


def _load_builtin() -> None:
    global _LOADED
    if not _LOADED:
        _LOADED = True
        for name in importlib.import_module(PACKAGE).BUILTIN:
            register(importlib.import_module(f"{PACKAGE}.{name}").FAMILY)


def register(family: Family, replace: bool = False) -> Family:
    """Make ``family`` available to observer files (``family = family.name``)."""
    _load_builtin()
    if not isinstance(family, Family):
        raise TypeError(f"register() takes a codegen.families.Family, got {type(family).__name__}")
    if family.name in _REGISTRY and not replace and _REGISTRY[family.name] is not family:
        raise ValueError(f"a family named {family.name!r} is registered already (replace=True to override)")
    _REGISTRY[family.name] = family
    return family


def unregister(name: str) -> None:
    _REGISTRY.pop(name, None)


def get(name: str) -> Family:
    _load_builtin()
    try:
        return _REGISTRY[name]
    except KeyError:
        from ..settings import suggest
        close = suggest(str(name), names())
        raise UnknownFamilyError(f"unknown observer family {name!r}" + (f" (did you mean {close!r}?)" if close else "")
                                 + f"; known: {', '.join(names())}",
                                 key="family", value=name, allowed=", ".join(names())) from None


def names() -> tuple:
    _load_builtin()
    return tuple(_REGISTRY)
