"""Automatic polytopes: nonlinearities found, exact forms exact, reduced form as eqs. (6)-(11)."""
import itertools

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


# -- premises of several scheduling signals (issue 42, item 7) ----------------------------------------
def _two_signal_lpv(tmp_path, entry: str, boxes: dict):
    """An LPV model x' = -entry x + d, y = x, with the scheduling boxes ``boxes`` {name: (lo, hi)}."""
    from codegen.model import ModelDefinition, SchedulingSignal, instantiate, load_parameters
    x, d = sp.symbols("x d")
    sig = {n: sp.Symbol(n, positive=lo > 0) if lo > 0 else sp.Symbol(n, real=True) for n, (lo, hi) in boxes.items()}
    J_e, J_w = sp.symbols("J_e J_w", positive=True)
    expr = sp.sympify(entry, locals={**sig, "J_e": J_e, "J_w": J_w})
    model = ModelDefinition(name="two_signals", states=(x,), known_inputs=(), unknown_inputs=(d,),
                            dynamics=sp.Matrix([-expr * x + d]), outputs=(("x", x),),
                            scheduling=tuple(SchedulingSignal(s) for s in sig.values()), parameters=(J_e, J_w))
    text = "[parameters]\nJ_e = 0.2\nJ_w = 1.1\n" + "".join(
        f"[scheduling.{n}]\nmin = {lo}\nmax = {hi}\nrate_min = -1.0\nrate_max = 1.0\n" for n, (lo, hi) in boxes.items())
    (tmp_path / "p.toml").write_text(text)
    return instantiate(model, load_parameters(tmp_path / "p.toml")), sig


@pytest.mark.parametrize("entry, boxes, exact", [
    # a_x crosses 0 in the numerator, v_x keeps the denominator away from 0: [-6/8, 4/8]
    ("a_x / v_x", {"v_x": (8.0, 40.0), "a_x": (-6.0, 4.0)}, (-0.75, 0.5)),
    # not a monomial: 1/(J(i_g) v_x), J = J_w + J_e i_g^2 (a gear ratio i_g in [1, 4])
    ("1 / ((J_w + J_e * i_g**2) * v_x)", {"v_x": (5.0, 40.0), "i_g": (1.0, 4.0)},
     (1 / ((1.1 + 0.2 * 16) * 40), 1 / ((1.1 + 0.2) * 5))),
])
def test_a_premise_of_several_signals_is_bounded_exactly(tmp_path, entry, boxes, exact):
    """A product or quotient of signals whose numerator crosses 0, and a premise that is no monomial,
    were refused ("non-monotone or singular", "not a monomial"): their range is the exact one, and the
    polytope reproduces A(rho) with memberships in [0, 1] everywhere in the box."""
    lpv, sig = _two_signal_lpv(tmp_path, entry, boxes)
    poly = P.sector_polytope(lpv, "none")
    (premise,) = poly.premises
    assert (premise.lower, premise.upper) == pytest.approx(exact, rel=1e-12)
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(*boxes[str(s)], 500) for s in lpv.scheduling_symbols])
    corners = np.array(list(itertools.product(*[boxes[str(s)] for s in lpv.scheduling_symbols])))
    exact_A = sp.lambdify(lpv.scheduling_symbols, lpv.A, "numpy")
    for rho in np.vstack([pts, corners]):
        eta = poly.eta(rho)
        assert np.all(eta >= -1e-12) and abs(eta.sum() - 1) < 1e-12
        np.testing.assert_allclose(np.einsum("i,ijk->jk", eta, poly.A), exact_A(*rho), rtol=1e-12, atol=1e-15)


def test_a_premise_that_cannot_be_enclosed_names_the_derived_signal_that_can(tmp_path):
    """A premise the interval arithmetic has no rule for (an erf of a quotient of two signals) is
    refused naming a derived scheduling signal; declared so, with its range, the polytope is built."""
    from codegen.errors import SchedulingBoundsError
    boxes = {"v_x": (5.0, 40.0), "a_x": (-6.0, 4.0)}
    lpv, sig = _two_signal_lpv(tmp_path, "erf(a_x / v_x)", boxes)
    with pytest.raises(SchedulingBoundsError, match=r"SchedulingSignal\(z, derived=<the expression>\) with its range "
                                                     r"in \[scheduling.z\]"):
        P.sector_polytope(lpv, "none")
    # the advice, applied: z derived from the input signals, bounded in [scheduling.z]
    from codegen.model import ModelDefinition, SchedulingSignal, instantiate, load_parameters
    x, d, z = sp.symbols("x d z")
    model = ModelDefinition(name="derived_z", states=(x,), known_inputs=(), unknown_inputs=(d,),
                            dynamics=sp.Matrix([-z * x + d]), outputs=(("x", x),),
                            scheduling=(SchedulingSignal(sig["v_x"]), SchedulingSignal(sig["a_x"]),
                                        SchedulingSignal(z, derived=sp.erf(sig["a_x"] / sig["v_x"]))),
                            parameters=())
    (tmp_path / "z.toml").write_text((tmp_path / "p.toml").read_text().replace("J_e = 0.2\nJ_w = 1.1\n", "")
                                     + "[scheduling.z]\nmin = -0.95\nmax = 0.75\nrate_min = -1.0\nrate_max = 1.0\n")
    poly = P.sector_polytope(instantiate(model, load_parameters(tmp_path / "z.toml")), "none")
    assert poly.n_vertices == 2 and (poly.premises[0].lower, poly.premises[0].upper) == (-0.95, 0.75)


def test_the_analysis_names_the_derived_signal_for_a_premise_that_cannot_be_enclosed(tmp_path):
    """``uiogen analyze`` gives the fix of that refusal (a derived scheduling signal), not "fix the box"."""
    from codegen import analysis
    (tmp_path / "m.py").write_text(
        "import sympy as sp\nfrom codegen.model import ModelDefinition, SchedulingSignal\n"
        "x, d, a_x = sp.symbols('x d a_x')\nv_x = sp.Symbol('v_x', positive=True)\n"
        "MODEL = ModelDefinition(name='erf_premise', states=(x,), known_inputs=(), unknown_inputs=(d,),\n"
        "    dynamics=sp.Matrix([-(2 + sp.erf(a_x / v_x)) * x + d]), outputs=(('x', x),),\n"
        "    scheduling=(SchedulingSignal(v_x), SchedulingSignal(a_x)), parameters=())\n")
    (tmp_path / "p.toml").write_text("[parameters]\n[scheduling.v_x]\nmin = 5.0\nmax = 40.0\nrate_min = -1.0\nrate_max = 1.0\n"
                                     "[scheduling.a_x]\nmin = -6.0\nmax = 4.0\nrate_min = -1.0\nrate_max = 1.0\n"
                                     "[inputs]\nd = { min = -1.0, max = 1.0 }\n")
    result = analysis.analyze(str(tmp_path / "m.py"), parameters=str(tmp_path / "p.toml"), design=False)
    fixes = [a.fix for a, _ in result.ranking.entries if "cannot be bounded" in a.condition]
    assert fixes and all("scheduling signal of its own" in f for f in fixes), fixes
