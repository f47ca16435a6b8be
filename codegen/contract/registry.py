"""The registry of observer families: the one place a family's name (an observer file's ``family = "..."``)
becomes the family.

The observer-file reader (:mod:`codegen.project.observer_file`) asks it once per file and hands the family
down on the configuration (``ObserverConfig.observer_family``); the stages below never look a family up.
The families that ship with uiogen are the packages ``codegen.families.NAME`` that ``codegen.families.BUILTIN``
lists, imported on first use as plug-ins are (:class:`codegen.plugins.Registry`: by the module's name,
nothing here imports a family); each defines ``FAMILY``, an instance of :class:`~codegen.contract.family.Family`.
"""
from __future__ import annotations

from ..errors import UnknownFamilyError
from ..plugins import Registry
from .family import Family


def _unknown(name, known) -> UnknownFamilyError:
    from ..settings import suggest
    close = suggest(str(name), known)
    return UnknownFamilyError(f"unknown observer family {name!r}" + (f" (did you mean {close!r}?)" if close else "")
                              + f"; known: {', '.join(known)}", key="family", value=name, allowed=", ".join(known))


FAMILIES = Registry("observer family", Family, "codegen.families", "FAMILY", _unknown)
"""Every family an observer file may name (``family = NAME``)."""

register, unregister, get, names = FAMILIES.register, FAMILIES.unregister, FAMILIES.get, FAMILIES.names
