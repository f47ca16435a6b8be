"""Discrete step: certificate proven, claim checked by simulation, unstable steps refused."""
import numpy as np
import pytest

from codegen.families.linf_uio import discrete
from codegen.families.linf_uio import design as linf_uio
from codegen.errors import DiscretizationError
from codegen.design.solver import FreshSolver


def test_certificate_contracts(build):
    """The committed design's certified figures (``uiogen design``; certify_step already refuses a
    step that does not contract, so what is asserted here is how much it does): kappa 1.0963,
    sqrt(V) contracts by 0.95506 per step; the UI filter loop by 0.97683 (beta 2.4 1/s), against the
    dense grid's 0.97327."""
    c = build.discrete_certificate
    assert c.kappa == pytest.approx(1.09632, abs=2e-4)
    assert c.contraction == pytest.approx(0.955060, abs=1e-4)
    assert c.contraction == pytest.approx(c.kappa ** -0.5, rel=1e-12)
    assert c.augmented_radius_max == pytest.approx(0.973271, abs=2e-4)
    # the UI filter loop: the bisection's decay, backed off to 90 % and rounded down to two digits
    assert c.ui_loop.beta == 2.4
    assert c.ui_loop.contraction == pytest.approx((1 + 2 * 2.4 * 0.01) ** -0.5, rel=1e-12)
    # the proof is tight against the grid's evidence
    assert 0.0 < c.ui_loop.contraction - c.augmented_radius_max < 0.005


def test_ui_loop_certificate_holds_along_random_scheduling(build):
    """The full error z = [e; e_d] of the backward-Euler step, UI filter loop closed, decreases
    V = z' P z by at least 1 + 2 beta Ts at every sample, for scheduling that jumps anywhere in
    the box (the common Lyapunov function does not need rate bounds)."""
    data, c = build.data, build.discrete_certificate.ui_loop
    sol = discrete._ui_loop_problem(data, c.beta, data.Tf, design=False).solve()
    P = np.asarray(sol["P"])
    scale = np.concatenate([np.ones(data.nx), 1.0 / discrete.ui_scaling(data.poly)])   # e_d in solver units
    rng = np.random.default_rng(3)
    poly = data.poly
    for _ in range(200):
        v = rng.uniform(poly.signal_lower, poly.signal_upper)
        Aa = discrete.augmented_matrices(data, np.array(discrete.premise_of_signal(poly, v), float))[0]
        z = rng.standard_normal(data.nz)
        z_next = np.linalg.solve(np.eye(data.nz) - data.Ts * Aa, z)
        V, V_next = (z * scale) @ P @ (z * scale), (z_next * scale) @ P @ (z_next * scale)
        assert V >= (1 + 2 * c.beta * data.Ts) * V_next * (1 - 1e-9)


def test_lyapunov_decrease_along_random_scheduling(build):
    """V_k >= kappa V_{k+1} for e_d = 0 along random speed sequences obeying |a_x| <= 4."""
    data, poly, c = build.data, build.poly, build.discrete_certificate
    rng = np.random.default_rng(7)
    Ts, amax = data.Ts, 4.0
    for _ in range(20):
        v = rng.uniform(poly.signal_lower, poly.signal_upper)
        e = rng.standard_normal(data.nx)
        for _ in range(200):
            v_next = np.clip(v + Ts * rng.uniform(-amax, amax), poly.signal_lower, poly.signal_upper)
            eta, eta_next = poly.eta(v), poly.eta(v_next)
            Q = sum(w * q for w, q in zip(eta, data.Q))
            Q_next = sum(w * q for w, q in zip(eta_next, data.Q))
            theta_next = np.array(discrete.premise_of_signal(poly, v_next), float)
            A_hat = discrete.augmented_matrices(data, theta_next)[0][:data.nx, :data.nx]
            e_next = np.linalg.solve(np.eye(data.nx) - Ts * A_hat, e)
            assert e @ Q @ e >= c.kappa * (e_next @ Q_next @ e_next) * (1 - 1e-9)
            e, v = e_next / np.linalg.norm(e_next), v_next


def test_numpy_and_casadi_steps_agree(build):
    f = build.step_function()
    rng = np.random.default_rng(1)
    for _ in range(50):
        z = rng.standard_normal(build.data.nz)
        u, y = rng.standard_normal(1), rng.standard_normal(3)
        rho = rng.uniform(0, 45)
        z_np, clamped = discrete.step_numpy(build.data, z, u, y, rho)
        z_ca, excess = f(z, u, y, rho)
        assert (float(excess) > 0) == bool(clamped)
        # two algorithms (5x5 LU in numpy, eliminated 4x4 QR in CasADi): normwise agreement
        z_ca = np.array(z_ca).ravel()
        assert np.abs(z_ca - z_np).max() <= 1e-11 * np.abs(z_np).max()
        assert clamped == float(not 5 <= rho <= 35)


@pytest.mark.slow       # 5 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_unstable_step_refused(build):
    """Gains that close an unstable loop through the UI filter (here the committed design's with
    the wrong sign; Q, hence kappa, unchanged) are refused: no step is emitted. The least-norm
    designs keep the loop stable up to gain bounds of 10^4 1/s (docs/families/linf_uio.md), so a
    high bound alone no longer provokes this."""
    data = discrete.ObserverData(build.poly, build.design.Q, tuple(-l for l in build.design.L), 0.005, 0.01)
    with pytest.raises(DiscretizationError, match="no common Lyapunov function.*unstable at v_x") as err:
        discrete.certify_step(data, 5.0, FreshSolver())
    assert "no filter constant up to" in str(err.value)      # measured: no Tf helps
    for gb in (1000.0, 10000.0):      # certify_step raises unless the step is certified
        fast = linf_uio.design(build.poly, linf_uio.LinfDesignSettings(gain_bound=gb), FreshSolver())
        discrete.certify_step(discrete.ObserverData(build.poly, fast.Q, fast.L, 0.005, 0.01), 5.0, FreshSolver())
