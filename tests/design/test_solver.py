"""A fresh solve and a replay of the design lock are two solver objects passed into a build
(codegen.design.solver): solutions are kept by problem name, a design with two problems of one
name is refused, a replay uses every committed solution, and LMIProblem.solve itself always
solves (no hidden state decides what it does)."""
import json

import numpy as np
import pytest

from codegen import pipeline
from codegen.design import lmi, lock as design_lock
from codegen.design.solver import FreshSolver, LockReplay, Solver
from codegen.errors import CertificateError, DesignLockError, LMIShapeError
from codegen.project import observer_file as observers


def _lyapunov(name: str = "lyapunov", design: bool = True, data: dict | None = None):
    prob = lmi.LMIProblem(name, design=design, data=data or {})
    P = prob.symmetric("P", 2)
    A = np.array([[-1.0, 2.0], [0.0, -3.0]])
    prob.require_psd("P > I", P, margin=1.0)
    prob.require_nsd("A'P + PA < 0", A.T @ P + P @ A, margin=1e-6)
    prob.minimize(lmi.trace(P))
    return prob


def test_both_solvers_satisfy_the_protocol():
    assert isinstance(FreshSolver(), Solver) and isinstance(LockReplay([]), Solver)


def test_fresh_solver_records_by_name_and_refuses_a_second_problem_of_the_same_name():
    solver = FreshSolver()
    sol = solver.solve(_lyapunov(data={"rate": 0.5}))
    assert [r.problem for r in solver.records] == ["lyapunov"] and solver.records[0].data == {"rate": 0.5}
    assert solver.committed_data("lyapunov") is None          # a fresh solve searches for its constants
    with pytest.raises(LMIShapeError, match="two LMI problems named 'lyapunov'"):
        solver.solve(_lyapunov())
    # an analysis problem (a bisection, a report) is solved, never recorded, and may repeat its name
    solver.solve(_lyapunov("bisection", design=False))
    solver.solve(_lyapunov("bisection", design=False))
    assert [r.problem for r in solver.records] == ["lyapunov"]
    # the replay of the record is the same solution, re-checked: bit-identical values
    replay = LockReplay(solver.records, source="test")
    again = replay.solve(_lyapunov(data={"rate": 0.5}))
    np.testing.assert_array_equal(again["P"], sol["P"])
    assert replay.committed_data("lyapunov") == {"rate": 0.5}
    replay.check_complete()


def test_a_trial_solver_answers_a_feasibility_design_by_its_first_point():
    """FreshSolver(least_norm=False) (analyze's trial designs, which commit nothing) hands a design
    problem without an objective its first certified point, not the least-norm one; a problem with
    an objective keeps its unique optimum, so a trial's gamma is the design's."""
    def feasibility():
        prob = lmi.LMIProblem("feasibility", design=True)
        P = prob.symmetric("P", 2)
        A = np.array([[-1.0, 2.0], [0.0, -3.0]])
        prob.require_psd("P > I", P, margin=1.0)
        prob.require_nsd("A'P + PA < 0", A.T @ P + P @ A, margin=1e-6)
        return prob
    first = feasibility().solve(unique=False)
    least = feasibility().solve(unique=True)
    trial = FreshSolver(least_norm=False).solve(feasibility())
    np.testing.assert_array_equal(trial["P"], first["P"])
    assert not np.array_equal(first["P"], least["P"])          # the two points differ on this problem
    assert all(c.certified for c in trial.checks)
    np.testing.assert_array_equal(FreshSolver().solve(feasibility())["P"], least["P"])
    np.testing.assert_array_equal(FreshSolver(least_norm=False).solve(_lyapunov())["P"],
                                  FreshSolver().solve(_lyapunov())["P"])


def test_progress_names_every_solve_once_the_design_has_run_long_enough():
    """A fresh solver reports each problem it solves (a design and an analysis alike, a failed one
    too); progress_after passes the lines on only after its delay, with the seconds elapsed."""
    from codegen.design.solver import progress_after
    lines = []
    solver = FreshSolver(progress=progress_after(lines.append, seconds=0.0))
    solver.solve(_lyapunov(data={"rate": 0.5}))
    solver.solve(_lyapunov("bisection", design=False))
    bad = lmi.LMIProblem("infeasible", design=False)
    P = bad.symmetric("P", 1)
    bad.require_psd("P > 0", P, margin=1e-6)
    bad.require_nsd("P < 0", P, margin=1e-6)
    with pytest.raises(Exception):
        solver.solve(bad)
    assert len(lines) == 3, lines
    assert lines[0].startswith("[0 s] lyapunov, rate = 0.5: 2 blocks, solved (") and lines[0].endswith(" s)")
    assert lines[1].startswith("[0 s] bisection: 2 blocks, solved (")
    assert lines[2].startswith("[0 s] infeasible: 2 blocks, infeasible or failed (")
    quiet = []
    FreshSolver(progress=progress_after(quiet.append, seconds=3600.0)).solve(_lyapunov())
    assert quiet == [] and progress_after(None) is None


def test_replay_refuses_what_does_not_fit():
    rec = FreshSolver()
    rec.solve(_lyapunov(data={"rate": 0.5}))
    [record] = rec.records
    with pytest.raises(DesignLockError, match="two committed LMI solutions for problem 'lyapunov'"):
        LockReplay([record, record], source="lock.json")
    replay = LockReplay([record], source="lock.json")
    with pytest.raises(DesignLockError, match="'other', which has no committed solution"):
        replay.solve(_lyapunov("other"))
    with pytest.raises(DesignLockError, match="used 0 of the 1 .*unused: 'lyapunov'"):
        replay.check_complete()
    with pytest.raises(DesignLockError, match="committed for"):          # built for other constants
        LockReplay([record]).solve(_lyapunov(data={"rate": 0.25}))
    replay = LockReplay([record])
    replay.solve(_lyapunov(data={"rate": 0.5}))
    with pytest.raises(LMIShapeError, match="two LMI problems named"):
        replay.solve(_lyapunov(data={"rate": 0.5}))
    broken = lmi.SolveRecord("lyapunov", {"P": [[-1.0, 0.0], [0.0, 1.0]]}, 0.0, 0, {"rate": 0.5})
    with pytest.raises(CertificateError, match="fails the numpy re-check"):   # P indefinite: no certificate
        LockReplay([broken]).solve(_lyapunov(data={"rate": 0.5}))


def test_lmi_problem_solve_always_solves():
    """No context decides what solve() does: inside a replay of another problem it still solves."""
    record = FreshSolver()
    record.solve(_lyapunov())
    replay = LockReplay(record.records)
    direct = _lyapunov().solve()
    assert direct.status == "Solved" and replay.solutions == {}


def test_the_lock_is_matched_by_problem_name_not_position():
    """The L-infinity design solves three problems; its lock's records in reverse order replay to
    the same build (same gains, same certificate), and one record short is refused by name."""
    config = observers.get("lpv_linf_driver_torque")
    data, why = design_lock.read(config)
    records = design_lock.solutions(data, "lock")
    assert len({r.problem for r in records}) == len(records) == 3
    forward = pipeline.build(config, LockReplay(records, "lock"))
    backward = pipeline.build(config, LockReplay(records[::-1], "lock"))
    for a, b in zip(forward.design.L, backward.design.L):
        np.testing.assert_array_equal(a, b)
    assert forward.certificate == backward.certificate
    with pytest.raises(DesignLockError, match="has no committed solution"):
        pipeline.build(config, LockReplay(records[1:], "lock"))
    extra = lmi.SolveRecord("not in this design", {}, 0.0, 0)
    with pytest.raises(DesignLockError, match="unused: 'not in this design'"):
        pipeline.build(config, LockReplay([*records, extra], "lock"))
    json.dumps([r.to_json() for r in records])
