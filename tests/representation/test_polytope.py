"""Automatic polytopes: nonlinearities found, exact forms exact, reduced form as eqs. (6)-(11)."""
import numpy as np
import pytest
import sympy as sp

from codegen.representation import polytope as P

from test_model import paper_A_w


def test_nonlinearities_found_automatically(lpv):
    vx = sp.Symbol("v_x", positive=True)
    assert set(P.scheduling_nonlinearities(lpv)) == {1 / vx, vx ** -2}


def test_sector_polytope_is_exact(lpv):
    poly = P.sector_polytope(lpv)
    assert poly.n_vertices == 4
    exact = P.exact_matrix_function(lpv, "A")
    for v in np.linspace(5, 35, 3001):
        eta = poly.eta(v)
        assert np.all(eta >= -1e-15) and abs(eta.sum() - 1) < 1e-14
        A_exact = exact(v)
        err = np.abs(np.einsum("i,ijk->jk", eta, poly.A) - A_exact).max()
        assert err <= 1e-12 * max(1.0, np.abs(A_exact).max())


def test_reduced_polytope_matches_paper(lpv):
    poly = P.taylor_reduced_polytope(lpv)
    vmin, vmax = 5.0, 35.0
    v0 = 2 * vmin * vmax / (vmin + vmax)
    v1 = -2 * vmin * vmax / (vmax - vmin)
    assert poly.n_vertices == 2 and poly.expansion_point == pytest.approx(v0)
    # theta of eq. (6): 1/vx = 1/v0 + theta/v1; theta = -1 at vmin, +1 at vmax; eta_1 = (1 - theta)/2
    for v in np.linspace(vmin, vmax, 50):
        theta = v1 * (1 / v - 1 / v0)
        assert poly.premise_values(v)[0] == pytest.approx(theta, abs=1e-13)
        np.testing.assert_allclose(poly.eta(v), [(1 - theta) / 2, (1 + theta) / 2], atol=1e-13)
    # vertices: A(theta) with 1/vx^2 replaced by its first-order Taylor expansion (6)
    for th, Ai in zip((-1.0, 1.0), poly.A):
        w = 1 / v0 + th / v1
        w2 = (1 + 2 * v0 / v1 * th) / v0 ** 2
        np.testing.assert_allclose(Ai, paper_A_w(w, w2), rtol=1e-12, atol=1e-12)


def test_taylor_error_is_reported_not_hidden(lpv):
    poly = P.taylor_reduced_polytope(lpv)
    err = P.taylor_error(lpv, poly)
    # the dropped term is theta^2/v1^2 times 2(lr Cr - lf Cf)/M on a12, largest at both ends
    v1 = -2 * 5 * 35 / 30
    coef = 2 * (1.6 * 59000 - 1.3 * 57000) / 2052
    assert err["entry"] == [0, 1]
    assert err["max_abs_error"] == pytest.approx(coef / v1 ** 2, rel=1e-9)


def test_rate_bounds_sound_and_paper(lpv):
    amax, vmin, vmax = 4.0, 5.0, 35.0
    v0 = 2 * vmin * vmax / (vmin + vmax)
    v1 = -2 * vmin * vmax / (vmax - vmin)
    a0 = -v0 ** 2 / v1
    paper = P.taylor_reduced_polytope(lpv, "at_expansion_point")
    np.testing.assert_allclose(paper.rate_bounds, [[-amax / (2 * a0), amax / (2 * a0)]] * 2, rtol=1e-12)
    exact = P.taylor_reduced_polytope(lpv, "exact")
    # eta_1' = -theta'/2, theta' = -v1 a_x / vx^2: largest at vmin
    bound = abs(v1) * amax / vmin ** 2 / 2
    np.testing.assert_allclose(exact.rate_bounds, [[-bound, bound]] * 2, rtol=1e-12)
    # soundness against sampling: every (vx, ax) in the box gives eta' inside the bounds
    for v in np.linspace(vmin, vmax, 301):
        for a in (-amax, 0.0, amax):
            eta_dot = -0.5 * (-v1 * a / v ** 2)
            assert exact.rate_bounds[0, 0] - 1e-12 <= eta_dot <= exact.rate_bounds[0, 1] + 1e-12
    # rate vertices are consistent: derivatives of the memberships sum to zero
    assert np.allclose(exact.rate_vertices.sum(axis=1), 0)
