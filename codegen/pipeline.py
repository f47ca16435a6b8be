"""The pipeline, in order: model -> representation -> design -> certificate -> discrete step.

:func:`build` runs every stage of the configuration's family (:mod:`codegen.families`) with the
solver it is given (:mod:`codegen.design.solver`: a fresh solve, or the committed design lock
replayed) and returns its build; :mod:`codegen.emit` turns it into C and
:mod:`codegen.extension.build` compiles that into a Python extension.
"""
from __future__ import annotations

from .design import lock as design_lock
from .design.solver import FreshSolver, LockReplay
from .design import precision
from .errors import BoundsError
from .project.observer_file import ObserverConfig


def committed(config: ObserverConfig):
    """The solver a plain build of ``config`` uses: its committed design lock replayed
    (:class:`LockReplay`) when the lock is current, else a :class:`FreshSolver`."""
    data, _ = design_lock.status(config)
    if data is None:
        return FreshSolver()
    return design_lock.replay(data, str(design_lock.path(config)))


def _family_build(config: ObserverConfig, solver):
    """The family's pipeline; an expression it cannot bound is reported with what the user can change:
    the boxes of the parameter file it was bounded over, and the family's bounds settings
    (``Family.bounds_settings``) where it has them."""
    family = config.observer_family
    from .model import load_parameters
    from .emit.stepgen import check_functions
    from .model.definition import check_signal_tables
    model = config.load_model()
    check_functions(model, config.model_path)
    check_signal_tables(model, load_parameters(config.parameter_path))
    try:
        return family.build(config, solver)
    except BoundsError as exc:
        if exc.singular:            # a division reaching 0 on the box: only the boxes can change that
            raise BoundsError(f"{config.parameter_path}: {exc}. A division needs its denominator nonzero on the "
                              f"whole box: {_boxes_to_move(config, exc.singular)} (observer {config.command_name})",
                              singular=exc.singular) from exc
        keys = " or ".join(f"[design] {k}" for k in family.bounds_settings)
        raise BoundsError(f"{config.parameter_path}: {exc}. The expression is bounded over the boxes this file "
                          f"declares ([scheduling.NAME], [state_bounds]): narrow those of the variables it ranges "
                          f"over" + (f", or loosen {keys} of {config.source}" if keys else "")
                          + f" (observer {config.command_name})") from exc


def _boxes_to_move(config: ObserverConfig, names: tuple) -> str:
    """Where the parameter file declares the boxes of ``names`` and what to set: a min above 0 for a
    box from 0 up (a speed), else a box that excludes 0."""
    from .model import load_parameters
    try:
        params = load_parameters(config.parameter_path)
        declared = {**{k: (f"[scheduling.{k}]", (b.lower, b.upper)) for k, b in params.scheduling.items()},
                    **{k: (f"[state_bounds] {k}", tuple(v)) for k, v in params.state_bounds.items()}}
    except Exception:           # the message stays useful without the file's tables
        declared = {}
    parts = []
    for name in names:
        table, (lo, hi) = declared.get(name, (f"the box of {name}", (None, None)))
        if lo is not None and lo >= 0:
            parts.append(f"{table} = [{lo:g}, {hi:g}] reaches 0: its min must be above 0")
        elif hi is not None and hi <= 0:
            parts.append(f"{table} = [{lo:g}, {hi:g}] reaches 0: its max must be below 0")
        elif lo is not None:
            parts.append(f"{table} = [{lo:g}, {hi:g}] contains 0: the box must exclude 0 (min above 0 or max "
                         f"below 0)")
        else:
            parts.append(f"{table} reaches 0: it must exclude 0 (min above 0 or max below 0)")
    return "; ".join(parts)


def build(config: ObserverConfig, solver=None):
    """The observer of ``config``, its design problems answered by ``solver``
    (:class:`~codegen.design.solver.FreshSolver` or :class:`~codegen.design.solver.LockReplay`);
    default :func:`committed`. A replay must use every committed solution. The unknown inputs of
    ``[substitute]`` are recovered after the family's step. Use :func:`solve` to also get the LMI
    solutions of a fresh design."""
    from .emit.substituted import wrap
    solver = committed(config) if solver is None else solver
    b = wrap(_checked(_family_build(config, solver)))
    if isinstance(solver, LockReplay):
        solver.check_complete()
        if solver.recorded is not None:        # what the lock reports is what its solutions give
            design_lock.check_reproduced(solver.recorded, b, solver.source,
                                         config.name if config.builtin else config.source)
    return b


def solve(config: ObserverConfig, tol: float | None = None, progress=None, least_norm: bool = True) -> tuple:
    """A fresh design of ``config`` and the LMI solutions it solved: (build, [SolveRecord]);
    ``progress``, ``least_norm``: see :class:`~codegen.design.solver.FreshSolver`."""
    solver = FreshSolver(tol, progress, least_norm)
    b = build(config, solver)
    return b, solver.records


def _checked(b):
    """``b``, refused when its ``[design] precision = "float32"`` margin is not certified
    (:mod:`codegen.design.precision`)."""
    precision.check(b)
    return b
