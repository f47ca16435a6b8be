"""Observer families: one folder each, one registry.

Each family lives in ``codegen/families/NAME/`` (``representation.py``, ``design.py``,
``build.py``, ``validation.py``, and an ``__init__.py`` defining ``FAMILY``, an instance of
:class:`~codegen.contract.family.Family`). The observer-file reader asks the registry
(:mod:`codegen.contract.registry`, re-exported here) and hands the family down on the configuration;
nothing compares family names:

>>> from codegen import families
>>> families.get("linf_uio").citation
'Nguyen, Guerra, Sentouh, Zhang, IEEE/ASME T-Mech 24(6), 2019'

A new family is one folder and one line in :data:`BUILTIN` (or, from outside the package,
``families.register(MyFamily())`` before loading its observer files); see ``README.md`` here.
"""
from __future__ import annotations

from ..contract.family import Family, ObserverBuild
from ..contract.registry import get, names, register, unregister

#: the families that ship with uiogen, imported on first use (each module defines ``FAMILY``)
BUILTIN = ("linf_uio", "ts_fuzzy_uio", "switched_pi", "algebraic_uio", "interconnected_uio",
           "nonlinear_tyre_observer", "dmvt_observer")

__all__ = ["Family", "ObserverBuild", "BUILTIN", "register", "unregister", "get", "names"]
