"""The pipeline, in order: model -> representation -> design -> certificate -> discrete step.

:func:`build` runs every stage of the configuration's family (:mod:`codegen.families`) with the
solver it is given (:mod:`codegen.design.solver`: a fresh solve, or the committed design lock
replayed) and returns its build; :mod:`codegen.emit` turns it into C and
:mod:`codegen.extension.build` compiles that into a Python extension.
"""
from __future__ import annotations

from .design import lock as design_lock
from .design.solver import FreshSolver, LockReplay
from . import families
from .project.observer_file import ObserverConfig


def committed(config: ObserverConfig):
    """The solver a plain build of ``config`` uses: its committed design lock replayed
    (:class:`LockReplay`) when the lock is current, else a :class:`FreshSolver`."""
    data, _ = design_lock.status(config)
    if data is None:
        return FreshSolver()
    return design_lock.replay(data, str(design_lock.path(config)))


def build(config: ObserverConfig, solver=None):
    """The observer of ``config``, its design problems answered by ``solver``
    (:class:`~codegen.design.solver.FreshSolver` or :class:`~codegen.design.solver.LockReplay`);
    default :func:`committed`. A replay must use every committed solution. Use :func:`solve` to
    also get the LMI solutions of a fresh design."""
    solver = committed(config) if solver is None else solver
    b = families.get(config.family).build(config, solver)
    if isinstance(solver, LockReplay):
        solver.check_complete()
    return b


def solve(config: ObserverConfig, tol: float | None = None) -> tuple:
    """A fresh design of ``config`` and the LMI solutions it solved: (build, [SolveRecord])."""
    solver = FreshSolver(tol)
    b = build(config, solver)
    return b, solver.records
