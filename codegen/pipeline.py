"""The pipeline, in order: model -> representation -> design -> certificate -> discrete step.

:func:`build` runs every stage of the configuration's family (:mod:`codegen.families`) and
returns its build; :mod:`codegen.emit` turns it into C and :mod:`codegen.extension.build` compiles
that into a Python extension. The design comes from the committed lock when it is current
(:mod:`codegen.design.lock`).
"""
from __future__ import annotations

from .design import lock as design_lock, lmi, precision
from . import families
from .errors import BoundsError
from .project.observer_file import ObserverConfig


def _family_build(config: ObserverConfig, tol: float | None):
    """The family's pipeline; an expression it cannot bound is reported with what the user can change:
    the boxes of the parameter file it was bounded over, and the family's bounds settings
    (``Family.bounds_settings``) where it has them."""
    family = families.get(config.family)
    try:
        return family.build(config, tol)
    except BoundsError as exc:
        keys = " or ".join(f"[design] {k}" for k in family.bounds_settings)
        raise BoundsError(f"{config.parameter_path}: {exc}. The expression is bounded over the boxes this file "
                          f"declares ([scheduling.NAME], [state_bounds]): narrow those of the variables it ranges "
                          f"over" + (f", or loosen {keys} of {config.source}" if keys else "")
                          + f" (observer {config.command_name})") from exc


def build(config: ObserverConfig, tol: float | None = None, fresh: bool = False):
    """The observer of ``config``: its committed design (:mod:`codegen.design.lock`) when it is
    current, replayed and re-checked block by block; otherwise (or with ``fresh`` or a solver
    ``tol``) a new solve. Use :func:`solve` to also get the LMI solutions for a new lock."""
    if not fresh and tol is None:
        data, _ = design_lock.status(config)
        if data is not None:
            where = str(design_lock.path(config))
            with lmi.replaying(design_lock.solutions(data, where), source=where):
                return _build(config, None)
    return _build(config, tol)


def _build(config: ObserverConfig, tol):
    """The family's stages, and the unknown inputs of ``[substitute]`` recovered after its step."""
    from .families.substituted import wrap
    return wrap(_checked(_family_build(config, tol)))


def solve(config: ObserverConfig, tol: float | None = None) -> tuple:
    """A fresh design of ``config`` and the LMI solutions it solved: (build, [SolveRecord])."""
    with lmi.recording() as ledger:
        b = _build(config, tol)
    return b, list(ledger.records)


def _checked(b):
    """``b``, refused when its ``[design] precision = "float32"`` margin is not certified
    (:mod:`codegen.design.precision`)."""
    precision.check(b)
    return b
