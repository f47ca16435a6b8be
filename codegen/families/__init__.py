"""Observer families: one folder each, one registry.

Each family lives in ``codegen/families/NAME/`` (``representation.py``, ``design.py``,
``build.py``, ``validation.py``, and an ``__init__.py`` defining ``FAMILY``, an instance of
:class:`~codegen.families.base.Family`). The toolchain asks this registry, never compares
family names:

>>> from codegen import families
>>> families.get("linf_uio").citation
'Nguyen, Guerra, Sentouh, Zhang, IEEE/ASME T-Mech 24(6), 2019'

A new family is one folder and one line in :data:`BUILTIN` (or, from outside the package,
``families.register(MyFamily())`` before loading its observer files); see ``README.md`` here.
"""
from __future__ import annotations

import importlib

from ..errors import UnknownFamilyError
from .base import Family, ObserverBuild

__all__ = ["Family", "ObserverBuild", "BUILTIN", "register", "unregister", "get", "names"]

#: the families that ship with uiogen, imported on first use (each module defines ``FAMILY``)
BUILTIN = ("linf_uio", "ts_fuzzy_uio", "switched_pi", "algebraic_uio", "interconnected_uio",
           "nonlinear_tyre_observer")

_REGISTRY: dict = {}
_LOADED = False


def _load_builtin() -> None:
    global _LOADED
    if not _LOADED:
        _LOADED = True
        for name in BUILTIN:
            register(importlib.import_module(f"{__name__}.{name}").FAMILY)


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
