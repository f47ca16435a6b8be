"""Who answers a design's LMI problems: a fresh solve, or the committed design lock replayed.

A family's pipeline never calls Clarabel for a design problem itself: it hands every design
problem (:class:`~codegen.design.lmi.LMIProblem` with ``design=True``) to the solver object it was
given, ``solver.solve(problem, tol=...)``, and asks it for the constants a design-time search
found (``solver.committed_data(name)``). Two solvers exist:

* :class:`FreshSolver` solves each problem with Clarabel (least-norm point, numpy re-check) and
  records it (:class:`~codegen.design.lmi.SolveRecord`) for a new design lock;
* :class:`LockReplay` solves nothing: it hands back the committed solution of each problem from a
  design lock (or a user's gains file), re-checked block by block like a fresh one.

Solutions are keyed by the problem's name: a design that solves two problems of the same name is
refused (:class:`~codegen.errors.LMIShapeError`), and a replay checks that every committed
solution was used. Analysis problems (``design=False``: a bisection, a report) are solved afresh
by either solver and never recorded.

Examples
--------
>>> solver = FreshSolver()
>>> build = family.build(config, solver)          # doctest: +SKIP
>>> records = solver.records                       # what the design lock commits
>>> replay = LockReplay(records, source="lock")
>>> again = family.build(config, replay)           # doctest: +SKIP
>>> replay.check_complete()                        # every committed solution was used
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

from ..errors import DesignLockError, LMIShapeError
from .lmi import LMIProblem, LMISolution, SolveRecord, exact_json

RESOLVE = "re-solve with `uiogen design NAME --update`"


@runtime_checkable
class Solver(Protocol):
    """What a family's pipeline asks of its solver."""

    #: solver tolerance that replaces the design settings' ``tol``; None: the settings'
    tol: float | None

    def solve(self, problem: LMIProblem, **options) -> LMISolution:
        """The re-checked solution of ``problem`` (``options``: those of :meth:`LMIProblem.solve`)."""

    def committed_data(self, problem: str) -> dict | None:
        """Constants found at design time for problem ``problem`` (see :attr:`LMIProblem.data`),
        when this solver holds them; None: search for them."""


PROGRESS_AFTER = 10.0
"""Seconds a design runs before its progress lines are shown: a quick one prints none."""


def progress_after(show, seconds: float = PROGRESS_AFTER):
    """A ``progress`` callback for :class:`FreshSolver` that hands each line to ``show``, prefixed with
    the seconds since it was made, once ``seconds`` have passed (None: ``show`` is None)."""
    if show is None:
        return None
    import time
    start = time.monotonic()

    def report(line: str) -> None:
        elapsed = time.monotonic() - start
        if elapsed >= seconds:
            show(f"[{elapsed:.0f} s] {line}")
    return report


def _refuse_twice(name: str, seen, what: str) -> None:
    if name in seen:
        raise LMIShapeError(f"the design {what} two LMI problems named {name!r}: solutions are kept by problem name, "
                            f"so every design problem needs its own (give the second one another name)")


class FreshSolver:
    """Solve every design problem with Clarabel and record its solution for a design lock.

    Parameters
    ----------
    tol : float, optional
        Solver tolerance that replaces the design settings' ``tol`` (a sweep, a tighter check);
        None keeps the settings'.
    progress : callable, optional
        Called with one line after every problem it solves (design, and the analyses a family hands
        it: a bisection's steps), naming the problem, its blocks, the outcome and the seconds taken.
    least_norm : bool, optional
        False: a design problem without an objective is answered by the solver's first feasible
        point instead of the least-norm one (:meth:`LMIProblem.solve`'s ``unique``), which only makes
        a committed solution the same on every machine: for a trial design that commits nothing
        (``uiogen analyze``). Every block is re-checked either way.
    """

    def __init__(self, tol: float | None = None, progress=None, least_norm: bool = True):
        self.tol = tol
        self.progress = progress
        self.least_norm = least_norm
        self._records: dict = {}       # problem name -> SolveRecord, in solve order

    @property
    def records(self) -> list:
        """The solved design problems' records, in solve order (the design lock's ``lmi_solutions``)."""
        return list(self._records.values())

    def solve(self, problem: LMIProblem, **options) -> LMISolution:
        if not problem.design:
            return self._timed(problem, options)
        _refuse_twice(problem.name, self._records, "solves")
        if not self.least_norm and not problem.has_objective:
            options = {**options, "unique": False}
        sol = self._timed(problem, options)
        self._records[problem.name] = SolveRecord(problem.name, exact_json(sol.values), sol.objective, sol.iterations,
                                                  dict(problem.data))
        return sol

    def committed_data(self, problem: str) -> None:
        return None

    def _timed(self, problem: LMIProblem, options: dict) -> LMISolution:
        if self.progress is None:
            return problem.solve(**options)
        import time
        start = time.perf_counter()
        what = problem.name + "".join(f", {k} = {v:.4g}" for k, v in problem.data.items() if isinstance(v, float))
        try:
            sol = problem.solve(**options)
        except Exception:
            self.progress(f"{what}: {problem.block_count} blocks, infeasible or failed "
                          f"({time.perf_counter() - start:.1f} s)")
            raise
        self.progress(f"{what}: {problem.block_count} blocks, solved ({time.perf_counter() - start:.1f} s)")
        return sol


class LockReplay:
    """Hand back committed solutions instead of solving, each re-checked block by block.

    Parameters
    ----------
    records : iterable of SolveRecord
        The committed solutions (a design lock's ``lmi_solutions``, or a user's gains file).
    source : str
        Where they come from, for the errors.

    Raises
    ------
    DesignLockError
        two records of one problem; a design problem without a record (at :meth:`solve`); a record
        no design problem used (at :meth:`check_complete`); a record that does not fit its problem.
    """

    tol = None

    def __init__(self, records, source: str = "", recorded: dict | None = None):
        self.source = source
        self.recorded = recorded        # the lock these records come from (its entries are checked by the pipeline)
        self._records: dict = {}
        for rec in records:
            if rec.problem in self._records:
                raise DesignLockError(f"{source}: two committed LMI solutions for problem {rec.problem!r}; {RESOLVE}")
            self._records[rec.problem] = rec
        self.solutions: dict = {}       # problem name -> the re-checked LMISolution, in use order

    @property
    def records(self) -> list:
        """The committed records the design used, in use order."""
        return [self._records[name] for name in self.solutions]

    def solve(self, problem: LMIProblem, **options) -> LMISolution:
        if not problem.design:
            return problem.solve(**options)
        _refuse_twice(problem.name, self.solutions, "asks for")
        rec = self._records.get(problem.name)
        if rec is None:
            held = ", ".join(repr(n) for n in self._records) or "none"
            raise DesignLockError(f"{self.source}: the design solves LMI problem {problem.name!r}, which has no committed "
                                  f"solution (committed: {held}); {RESOLVE}")
        try:
            sol = problem.replay(rec)
        except DesignLockError as exc:
            raise DesignLockError(f"{self.source}: {exc}") from None
        self.solutions[problem.name] = sol
        return sol

    def committed_data(self, problem: str) -> dict | None:
        rec = self._records.get(problem)
        return None if rec is None else dict(rec.data)

    def check_complete(self) -> None:
        """Refuse a replay that left committed solutions unused (the design changed shape)."""
        unused = [name for name in self._records if name not in self.solutions]
        if unused:
            raise DesignLockError(f"{self.source}: the design used {len(self.solutions)} of the {len(self._records)} "
                                  f"committed LMI solutions (unused: {', '.join(map(repr, unused))}); {RESOLVE}")
