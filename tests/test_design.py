"""Theorem 1 design: certified, well posed, reproducible; published gains checked on our model."""
import numpy as np
import pytest

from codegen import pipeline, polytope
from codegen.families.linf_uio import design as linf_uio
from codegen.errors import RankConditionError


def test_design_certified_and_rechecked(build):
    d, sol = build.design, build.design.solution
    assert all(c.min_eig >= 0 for c in sol.checks)
    # independent numpy re-check of the rounded matrices certifies (at most) the design gamma
    assert build.certificate["feasible"]
    assert build.certificate["gamma"] <= d.gamma * (1 + 1e-6)
    assert build.certificate["gamma"] == pytest.approx(d.gamma, rel=2e-3)


def test_pdlf_never_worse_than_quadratic(build):
    assert build.design.gamma <= build.quadratic.gamma * (1 + 1e-6)


def test_gain_bound_holds_over_the_box(build):
    bound = build.design.settings.gain_bound
    for v in np.linspace(build.poly.signal_lower, build.poly.signal_upper, 301):
        M = linf_uio.gain_at(build.poly, build.design.Q, build.design.L, v)
        assert np.linalg.norm(M, 2) <= bound * (1 + 1e-9)


def test_gamma_reproducible_under_tighter_tolerance(config, build):
    tight = pipeline.build(config, tol=1e-9)
    assert build.design.settings.tol > 1e-9
    assert abs(tight.design.gamma - build.design.gamma) / build.design.gamma < 0.01


def test_pdlf_and_lyapunov_decrease_on_continuum(build):
    """The certified inequality (31) at random (theta, theta_dot) inside the box, not only at vertices."""
    poly, d = build.poly, build.design
    rng = np.random.default_rng(3)
    a = d.settings.alpha
    for _ in range(200):
        v = rng.uniform(poly.signal_lower, poly.signal_upper)
        eta = poly.eta(v)
        rate = rng.uniform(poly.rate_bounds[0, 0], poly.rate_bounds[0, 1])
        Q = sum(e * q for e, q in zip(eta, d.Q))
        L = sum(e * l for e, l in zip(eta, d.L))
        A = poly.A_of(v)
        Pdot = rate * (d.Q[0] - d.Q[1])
        W = Q @ A + L @ poly.C[0]
        lhs = W + W.T + 2 * a * Q + Pdot
        assert np.linalg.eigvalsh(lhs).max() < 0


def test_published_gains_pass_theorem1(lpv, published):
    P = [published["P1"], published["P2"]]
    L = [published["L1"], published["L2"]]
    for mode in ("exact", "at_expansion_point"):
        poly = polytope.taylor_reduced_polytope(lpv, mode)
        res = linf_uio.certify(poly, P, published["X"], L, published["alpha"])
        assert res["feasible"], mode
        # mu >= 1/lambda_min(P_i + X) alone is 0.0076 > 0.002^2/nu for any reachable nu
        assert 0.009 < res["gamma"] < 0.0100
        assert res["mu"] == pytest.approx(1 / min(np.linalg.eigvalsh(np.array(p) + np.array(published["X"])).min()
                                                  for p in P), rel=1e-9)


def test_published_p1_is_indefinite_as_the_paper_says(published):
    assert np.linalg.eigvalsh(np.array(published["P1"])).min() < 0


def test_rank_and_detectability_failures(lpv):
    poly = polytope.taylor_reduced_polytope(lpv)
    no_ui = polytope.Polytope(**{**poly.__dict__, "D": np.zeros_like(poly.D)})
    with pytest.raises(RankConditionError, match="full column rank"):
        linf_uio.build_problem(no_ui, linf_uio.LinfDesignSettings())
    # measure only the steering rate: with an unstable mode added, (A, C) is not detectable
    A = poly.A.copy()
    A[:, 0, 0] = 1.0
    A[:, 0, 1:] = 0.0
    A[:, 1:, 0] = 0.0
    blind = polytope.Polytope(**{**poly.__dict__, "A": A})
    with pytest.raises(RankConditionError, match="not detectable"):
        linf_uio.build_problem(blind, linf_uio.LinfDesignSettings())


def test_infeasible_design_is_a_typed_error(lpv):
    from codegen.errors import InfeasibleLMIError
    poly = polytope.taylor_reduced_polytope(lpv)
    with pytest.raises(InfeasibleLMIError, match="\\(21\\)|gain bound|\\(20\\)"):
        linf_uio.design(poly, linf_uio.LinfDesignSettings(alpha=200.0, gain_bound=1.0))
