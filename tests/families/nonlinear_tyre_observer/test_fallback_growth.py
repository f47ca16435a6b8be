"""``[design] fallback_growth``: the kinematic fallback beyond the certified slip set, certified too.

The claim (docs/families/nonlinear_tyre_observer.md, "Certifying the fallback"): the gains are designed
with a Lyapunov matrix that the fallback's error step expands by at most 1 + T_s eps_fb, whatever the
true slip, on a sample flagged for its estimated slip alone. Checked here on the model itself (its own
Euler step and a_y), not on the family's factorization, and against the design without it.
"""
import dataclasses

import numpy as np
import pytest

from codegen import families
from codegen.design.solver import FreshSolver, LockReplay
from codegen.errors import ConfigurationError
from codegen.families.nonlinear_tyre_observer import design as dsn
from codegen.project import observer_file as observers

from test_through_sliding import _model_functions

NAME = "stanford_sideslip_nonlinear_tyre"
FAMILY = families.get("nonlinear_tyre_observer")
GROWTH = 20.0


def _with(config, **more):
    return dataclasses.replace(config, design={**config.design, **more})


@pytest.fixture(scope="module")
def built():
    solver = FreshSolver()
    b = FAMILY.build(_with(observers.get(NAME), fallback_growth=GROWTH), solver)
    return b, solver


def test_the_fallback_step_expands_v_at_most_as_claimed_at_any_true_slip(built):
    b, _ = built
    assert b.recheck["fallback_growth"] == GROWTH
    assert b.recheck["blocks"] == 1 + 8 + 16 + 1 + 16 + 8          # + one fallback block per (s, theta_f, theta_r)
    assert "eps_fb = 20 1/s" in b.certificate.claim
    f, a_y, _, ratio = _model_functions(b.config)
    Ts, D = b.config.sample_time, b.plant.D
    P = D.T @ b.P @ D
    rng = np.random.default_rng(11)
    flagged, worst = 0, 0.0
    for _ in range(3000):
        u = [rng.uniform(-0.2, 0.2), rng.uniform(-15, 10)]
        v = rng.uniform(15, 65)
        x = np.array([rng.uniform(-6, 6), rng.uniform(-0.6, 0.6)])          # the true state: any slip
        xh = np.array([rng.uniform(-8, 8), x[1] + rng.uniform(-0.05, 0.05)])
        z, excess = b.reference_step(np.array([*xh, 0.0, 0.0]), u, [a_y(*x, *u, v), x[1]], [v])
        if excess == 0:
            continue                                                        # the tyre step: the decay's claim
        flagged += 1
        x_next = x + Ts * np.array([fn(*x, *u, v) for fn in f])
        e, e_next = x - xh, x_next - z[:2]
        ratio_v = float(e_next @ P @ e_next) / float(e @ P @ e)
        assert ratio_v <= (1.0 + Ts * GROWTH) * (1 + 1e-9)
        worst = max(worst, ratio_v)
    assert flagged > 500 and worst > 1.0          # the bound is reached for, not vacuous


def test_without_it_the_fallback_expands_v_beyond_that(built):
    # the committed design (no fallback_growth): at some vertex of the fallback's error step its P grows by
    # more than 1 + Ts 20, which the designed one does not
    plain = FAMILY.build(observers.get(NAME), FreshSolver())
    b, _ = built
    Ts = plain.config.sample_time

    def growth(build):
        out = 0.0
        for x in dsn.fallback_vertices(build.decay_verts):
            A = np.array([[1.0, 0.0], [Ts * (build.plant.G_f @ x.theta)[1] * x.s, 0.0]])
            Ah = build.plant.D @ A @ np.linalg.inv(build.plant.D)
            out = max(out, float(np.max(np.linalg.eigvals(np.linalg.solve(build.P, Ah.T @ build.P @ Ah)).real)))
        return out
    assert growth(plain) > 1.0 + Ts * GROWTH >= growth(b)


def test_it_is_recorded_in_the_lock_and_replayed(built):
    b, solver = built
    data = {r.problem: r.data for r in solver.records}
    assert any(d.get("fallback_growth") == GROWTH for d in data.values())
    replay_solver = LockReplay(solver.records, source="test")
    again = FAMILY.build(_with(observers.get(NAME), fallback_growth=GROWTH), replay_solver)
    replay_solver.check_complete()
    assert np.array_equal(again.L, b.L) and again.recheck["fallback_growth"] == GROWTH


def test_with_through_sliding_it_is_one_typed_line():
    with pytest.raises(ConfigurationError, match="fallback_growth = 20 certifies the kinematic fallback"):
        FAMILY.build(_with(observers.get(NAME), fallback_growth=GROWTH, through_sliding=True), FreshSolver())
