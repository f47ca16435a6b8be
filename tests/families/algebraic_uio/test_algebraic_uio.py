"""Ichalal and Mammar 2015: relative degree and decoupling derived, classical UIO refused,
LMI (39) and discrete certificates, the compiled step against CasADi and numpy, the examples' targets."""
import dataclasses
import math

import numpy as np
import pytest
import sympy as sp

from codegen.project import observer_file as observers
from codegen import pipeline
from codegen.families.algebraic_uio import build as algebraic_uio
from codegen.families.algebraic_uio import representation as rdeg
from codegen.families.algebraic_uio import design as alg
from codegen.errors import (DiscretizationError, InfeasibleLMIError, ModelDefinitionError, RankConditionError,
                           SchedulingBoundsError)
from codegen.model import ModelDefinition, SchedulingSignal, instantiate, load_parameters
from codegen.project.observer_file import ObserverConfig
from codegen.design.solver import FreshSolver

NAMES = ("algebraic_uio_example1", "algebraic_uio_example2", "algebraic_uio_lateral_force")


@pytest.fixture(scope="module")
def builds(built):
    return {n: built(n) for n in NAMES}


def _lpv(name):
    cfg = observers.get(name)
    return instantiate(cfg.load_model(), load_parameters(cfg.parameter_path))


def _eq(a, b):
    return sp.simplify(sp.Matrix(a) - sp.Matrix(b)) == sp.zeros(*sp.Matrix(a).shape)


# ---- item 1: relative degree and decoupling, derived ---------------------------------------------------

def test_example1_matrices_are_the_seeds(builds):
    dec = builds["algebraic_uio_example1"].dec
    rho = dec.base[0]
    assert dec.relative_degrees == (1,)
    assert _eq(dec.Q, [[1], [(1 + rho) / rho]])                                   # eq. (50)
    assert _eq(dec.P, [[0, 0], [-(1 + rho) / rho, 1]])
    assert _eq(dec.F0, [[0, 0], [-rho, -(1 + rho) ** 2 / rho - 2]])              # P A of eq. (51)
    assert _eq(dec.F0, dec.P * dec.lpv.A)


def test_example2_matrices_are_the_seeds(builds):
    dec = builds["algebraic_uio_example2"].dec
    rho = dec.base[0]
    rho_d = rdeg.derivative_symbol(rho, 1)
    assert dec.relative_degrees == (2,)
    assert _eq(dec.M[0][1], [[0, 1 + rho]])
    assert _eq(dec.M[0][2], [[-rho * (1 + rho), rho_d - 2 * rho - 2]])       # M_2 with the rho' of M_1'
    assert _eq(dec.Gamma, [[(1 + rho) ** 2]])
    assert _eq(dec.Q, [[0], [1 / (rho + 1)]])
    assert _eq(dec.F0, [[0, rho + 1], [0, (-rho_d + 2 * rho + 2) / (rho + 1) - 2]])   # eq. (69)
    assert dec.derivative_orders == {rho: 1}
    # the 4-vertex polytope over rho and rho_2 of (71): our premise rho'/(rho + 1) = 2 - rho_2
    prem = builds["algebraic_uio_example2"].design.gain_polytope.premises
    assert len(prem) == 2 and {str(p.expr) for p in prem} == {"rho", "rho_d1/(rho + 1)"}


def test_example3_relative_degree_three_with_speed_derivatives():
    lpv = _lpv("algebraic_uio_lateral_force")
    dec = rdeg.derive(lpv)                  # the paper's model (81) itself (no output injection)
    v = dec.base[0]
    p = lpv.parameters.values
    l, Iz, sig = p["l_f"] + p["l_r"], p["I_z"], p["sigma_r"]
    assert dec.relative_degrees == (3,)
    assert dec.derivative_orders == {v: 2}                       # M_3 holds v_x''
    g = float(sp.N(dec.Gamma[0] / v ** 2))
    assert g == pytest.approx(l / (Iz * sig), rel=1e-12)         # M_2 D = v_x^2 l / (I_z tau_r)
    assert float(sp.N(dec.Q[2] * v)) == pytest.approx(Iz / l, rel=1e-12)
    vd2 = rdeg.derivative_symbol(v, 2)
    assert float(sp.N(sp.diff(dec.F0[2, 1], vd2) * v)) == pytest.approx(Iz / l, rel=1e-12)


def _lie_derivatives(lpv, order):
    """y^(j), j = 0..order, by differentiating along x' = f(x, u, d, rho) with every signal time-varying."""
    d = lpv.definition
    exact = lambda m: m.applyfunc(lambda e: sp.nsimplify(e, rational=True))     # no float round-off residue
    lpv = dataclasses.replace(lpv, A=exact(lpv.A), B=exact(lpv.B), C=exact(lpv.C), D=exact(lpv.D))
    f = lpv.A * sp.Matrix(d.states) + lpv.B * sp.Matrix(len(d.known_inputs), 1, list(d.known_inputs)) \
        + lpv.D * sp.Matrix(d.unknown_inputs)
    chains = (*lpv.scheduling_symbols, *d.unknown_inputs, *d.known_inputs)
    out = [lpv.C * sp.Matrix(d.states)]
    for _ in range(order):
        e = out[-1]
        de = e.jacobian(sp.Matrix(d.states)) * f
        for sym in set().union(*(x.free_symbols for x in e)) - set(d.states):
            k, m = rdeg.derivative_order(sym, chains)
            de += sp.diff(e, sym) * rdeg.derivative_symbol(chains[k], m + 1)
        out.append(sp.simplify(de))
    return out


@pytest.mark.parametrize("name", NAMES)
def test_output_derivatives_match_the_derivation(name):
    """Independent path: y^(j) along the trajectories. d (and its derivatives) is absent below r, and
    y^(r) - Mcal x - Gamma d depends neither on x nor on d (only on known inputs)."""
    lpv = _lpv(name)
    dec = rdeg.derive(lpv)
    r = dec.relative_degrees[0]
    ys = _lie_derivatives(lpv, r)
    d = lpv.definition
    uis = set(d.unknown_inputs)
    ui_derivs = {rdeg.derivative_symbol(s, m) for s in d.unknown_inputs for m in range(1, r + 1)}
    for j in range(r):
        assert not (ys[j][0].free_symbols & (uis | ui_derivs)), (j, ys[j])
    rest = sp.simplify(ys[r][0] - (dec.Mcal * sp.Matrix(d.states))[0] - (dec.Gamma * sp.Matrix(d.unknown_inputs))[0])
    assert not (rest.free_symbols & (set(d.states) | uis | ui_derivs)), rest


def _write_params(tmp_path, name, sched="rho", lo=1.0, hi=5.0, extra=""):
    p = tmp_path / f"{name}.toml"
    p.write_text(f"[parameters]\n\n[scheduling.{sched}]\nmin = {lo}\nmax = {hi}\nrate_min = -2.0\nrate_max = 2.0\n{extra}")
    return load_parameters(p)


def _remark2_model(outputs):
    x1, x2, x3, x4, d1, d2 = sp.symbols("x1 x2 x3 x4 d1 d2")
    rho = sp.Symbol("rho", positive=True)
    A = sp.Matrix([[0, 1, 0, 0], [0, -rho, 0, -1], [0, 0, 0, 1], [0, 0, -1, 0]])
    D = sp.Matrix([[0, 0], [rho, 0], [1, 0], [0, 1]])
    x = sp.Matrix([x1, x2, x3, x4])
    states = {"x1": x1, "x2": x2, "x3": x3, "x4": x4}
    return ModelDefinition("remark2", (x1, x2, x3, x4), (), (d1, d2), A * x + D * sp.Matrix([d1, d2]),
                           tuple((o, states[o]) for o in outputs), (SchedulingSignal(rho),), ())


def test_rank_condition_64_fails_for_the_seeds_remark2_system(tmp_path):
    """(87)-(88): r = (2, 1) and Gamma = [[rho, 0], [1, 0]] (90), singular for every rho."""
    lpv = instantiate(_remark2_model(("x1", "x3")), _write_params(tmp_path, "r2"))
    with pytest.raises(RankConditionError, match=r"\(64\).*singular for every parameter"):
        rdeg.derive(lpv)


def test_nonuniform_relative_degree_is_refused(tmp_path):
    x1, x2, d = sp.symbols("x1 x2 d")
    rho = sp.Symbol("rho", positive=True)
    m = ModelDefinition("nonuniform", (x1, x2), (), (d,), sp.Matrix([x2 + (rho - 2) * d, -x1 - x2 + d]),
                        (("x1", x1),), (SchedulingSignal(rho),), ())
    lpv = instantiate(m, _write_params(tmp_path, "nu"))
    with pytest.raises(rdeg.RelativeDegreeError, match="vanishes on the box"):
        rdeg.derive(lpv)


def test_missing_derivative_bound_is_a_clear_error(tmp_path):
    lpv = _lpv("algebraic_uio_lateral_force")
    src = (tmp_path / "p.toml")
    text = open(lpv.parameters.source).read()
    src.write_text("\n".join(line for line in text.splitlines() if not line.startswith("derivative_bounds")))
    with pytest.raises(SchedulingBoundsError, match="v_x_d2"):
        rdeg.derive(dataclasses.replace(lpv, parameters=load_parameters(src)))


# ---- several outputs / UIs: Gamma, its inverse and pseudo-inverse, and an observer that converges ----------

def _mimo_model(outputs):
    """x1' = x2, x2' = -rho x1 - x2 + rho d1, x3' = x1 - x3 + d2: strongly observable from (x1, x3)."""
    x1, x2, x3, d1, d2 = sp.symbols("x1 x2 x3 d1 d2")
    rho = sp.Symbol("rho", positive=True)
    states = {"x1": x1, "x2": x2, "x3": x3}
    return ModelDefinition("mimo", (x1, x2, x3), (), (d1, d2),
                           sp.Matrix([x2, -rho * x1 - x2 + rho * d1, x1 - x3 + d2]),
                           tuple((o, states[o]) for o in outputs), (SchedulingSignal(rho),), ())


def _mimo_build(tmp_path, outputs):
    model = _mimo_model(outputs)
    # the state box weighs the left inverse of a non-square Gamma (representation.left_inverse)
    params = _write_params(tmp_path, "mimo", extra="\n[state_bounds]\nx1 = [-1.0, 1.0]\nx2 = [-2.0, 2.0]\n"
                                                   "x3 = [-1.0, 1.0]\n")
    lpv = instantiate(model, params)
    spec = {"order": 5, "lipschitz": 2e4}
    cfg = ObserverConfig("mimo_test", "algebraic_uio", "none", "mimo.toml", "", "exact", 0.001,
                         {"lmi": "direct", "alpha": 3.0, "margin": 1e-4,
                          "differentiators": {**{f"y_{o}": spec for o in outputs}, "rho": {"order": 5, "lipschitz": 50.0}}},
                         {}, "", str(tmp_path / "mimo.toml"))
    return algebraic_uio.build(cfg, FreshSolver(), lpv=lpv), lpv


@pytest.mark.slow       # 4 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
@pytest.mark.parametrize("outputs", [("x1", "x3"), ("x1", "x3", "x2")])
def test_mimo_gamma_inverse_and_convergence(tmp_path, outputs):
    """y1 = x1, y2 = x3 (r = (2, 1), Gamma = diag(rho, 1)); with y3 = x2 Gamma is 3x2 and the
    pseudo-inverse (86) is used. The observer (85)/(86) built by the pipeline converges on the plant."""
    (tmp_path / "mimo.toml").write_text("")
    b, lpv = _mimo_build(tmp_path, outputs)
    dec = b.dec
    rho = dec.base[0]
    assert dec.relative_degrees == ((2, 1) if len(outputs) == 2 else (2, 1, 1))
    assert _eq(dec.Gamma_inv * dec.Gamma, sp.eye(2))
    assert _eq(dec.P * lpv.D, sp.zeros(3, 2))
    # simulate the plant with rho(t), d(t) and run the CasADi step (the C kernel's graph)
    from scipy.integrate import solve_ivp
    h, T = b.config.sample_time, 12.0
    rho_f = lambda t: 3 + 1.5 * np.sin(0.5 * t)
    d_f = lambda t: np.array([0.3 * np.sin(1.3 * t), 0.2 * np.cos(0.7 * t) + 0.1])
    A = sp.lambdify(rho, lpv.A, "numpy")
    D = sp.lambdify(rho, lpv.D, "numpy")
    sol = solve_ivp(lambda t, x: np.asarray(A(rho_f(t)), float) @ x + np.asarray(D(rho_f(t)), float) @ d_f(t),
                    (0, T), [0.5, 0.0, -0.3], method="DOP853", rtol=1e-12, atol=1e-13, dense_output=True)
    t = np.arange(int(T / h) + 1) * h
    X = sol.sol(t).T
    C = np.array(lpv.C, dtype=float)
    f = b.step_function().mapaccum(t.size)
    Z = np.array(f(np.zeros(b.n_state), np.zeros((0, t.size)), (X @ C.T).T, rho_f(t)[None, :])[0]).T
    est = Z[:, -5:]
    late = t >= 9.0
    assert np.abs(est[late, :3] - X[late]).max() / np.abs(X).max() < 1e-6
    dd = np.array([d_f(tt) for tt in t])
    assert np.abs(est[late, 3:] - dd[late]).max() / np.abs(dd).max() < 1e-6


# ---- item 2: classical vs proposed ---------------------------------------------------------------------

def test_classical_uio_does_not_exist_for_example1(builds):
    """(47)-(48): h = (-1, -6/5) at rho = 5 and (-1, -2) at rho = 1, no common H, although
    rank(C D_i) = rank(D_i) at both vertices."""
    c = builds["algebraic_uio_example1"].classical
    assert not c["exists"]
    hs = sorted(tuple(np.round(np.ravel(v["H"]), 12)) for v in c["vertices"])
    assert hs == [(-1.0, -2.0), (-1.0, -1.2)]
    assert all(v["rank_CD"] == v["rank_D"] == 1 for v in c["vertices"])
    assert "no common H" in c["reason"]
    c2 = builds["algebraic_uio_example2"].classical
    assert not c2["exists"] and "matching condition" in c2["reason"]


def test_classical_uio_exists_when_D_has_a_fixed_direction(tmp_path):
    x1, x2, d = sp.symbols("x1 x2 d")
    rho = sp.Symbol("rho", positive=True)
    m = ModelDefinition("fixed", (x1, x2), (), (d,), sp.Matrix([(1 + rho) * x2 + rho * d, -rho * x1 - 2 * x2 + 2 * rho * d]),
                        (("x1", x1),), (SchedulingSignal(rho),), ())
    lpv = instantiate(m, _write_params(tmp_path, "fx"))
    c = alg.classical_uio(lpv, rdeg.derivative_boxes(lpv))
    assert c["exists"] and np.allclose(c["common_H_least_squares"], [[-1.0], [-2.0]])


def test_lmi_and_discrete_certificates(builds):
    for name, b in builds.items():
        assert b.recheck["worst_min_eig"] > 0 and b.dense["max_eig"] < 0
        dc = b.discrete
        assert dc["h_a_f"] < 1 and dc["contraction_bound_per_step"] < 1
        assert dc["sampled_amplification_X_norm_max"] <= dc["contraction_bound_per_step"] + 1e-12
        if dc["h_a_f"] < 0.05:      # small steps: the bound is close to the continuous decay exp(-alpha h)
            assert dc["contraction_bound_per_step"] <= math.exp(-0.9 * b.settings.alpha * b.config.sample_time)
    cmp = builds["algebraic_uio_example1"].compare       # the paper's hand gain (52), l = (3, 0)
    assert cmp["certified"] and cmp["alpha"] == pytest.approx(3.0, abs=1e-3)


def test_fixed_modes_are_the_invariant_zeros(builds):
    """Example 1: the error mode -((1+rho)^2/rho + 2) of (51) is unobservable from C, so no gain moves it
    (it bounds the decay of any UIO of (40)); Example 2's pair is observable everywhere."""
    fm = builds["algebraic_uio_example1"].design.fixed_modes
    rho = np.linspace(1.0, 5.0, 401)
    zeros = -((1 + rho) ** 2 / rho + 2)
    assert fm["count"] == 1
    assert fm["real_range"] == pytest.approx([zeros.min(), zeros.max()], abs=1e-9)   # corners are sampled
    assert fm["decay_limit"] == pytest.approx(6.0, abs=1e-9)
    # the gain cannot move it: the eigenvalue is there in F0 - L C for the designed gains too
    for _, F in builds["algebraic_uio_example1"].design.closed_loop:
        assert np.isclose(np.linalg.eigvals(F), F[1, 1]).any()
    for name in ("algebraic_uio_example2", "algebraic_uio_lateral_force"):
        assert builds[name].design.fixed_modes["count"] == 0


def test_decay_rate_beyond_the_fixed_modes_is_refused(builds):
    b = builds["algebraic_uio_example1"]
    with pytest.raises(InfeasibleLMIError, match=r"invariant zeros.*alpha < 6"):
        alg.design(b.dec, dataclasses.replace(b.settings, alpha=6.5), FreshSolver())


def test_gauss_step_is_b_stable_at_large_steps(builds):
    """Algebraic stability: V(e+) <= V(e) for any stage matrices in the polytope, whatever h."""
    d = builds["algebraic_uio_example2"].design
    R = np.linalg.cholesky(d.X).T
    Ri = np.linalg.inv(R)
    mats = [F for _, F in d.closed_loop]
    rng = np.random.default_rng(3)
    for h in (0.01, 0.1, 1.0, 10.0):
        for _ in range(200):
            pick = [sum(w * m for w, m in zip(rng.dirichlet(np.ones(len(mats))), mats)) for _ in range(2)]
            assert np.linalg.norm(R @ alg.amplification(pick, h) @ Ri, 2) <= 1.0 + 1e-12


def test_open_loop_auxiliary_system_is_refused_for_example3():
    cfg = observers.get("algebraic_uio_lateral_force")
    cfg = dataclasses.replace(cfg, design={**cfg.design, "auxiliary": "open_loop"})
    with pytest.raises(DiscretizationError, match="common quadratic Lyapunov"):
        pipeline.build(cfg)


def test_differentiator_order_below_relative_degree_is_refused():
    cfg = observers.get("algebraic_uio_example2")
    diffs = {**cfg.design["differentiators"], "y_x1": {"order": 1, "lipschitz": 10.0}}
    with pytest.raises(ModelDefinitionError, match="needs derivative 2"):
        pipeline.build(dataclasses.replace(cfg, design={**cfg.design, "differentiators": diffs}))


# ---- the step: C == CasADi, C ~ numpy -------------------------------------------------------------------

@pytest.mark.slow          # the compiled observers
@pytest.mark.parametrize("name", NAMES)
def test_c_step_matches_casadi_and_numpy(builds, name):
    from python_bindings import load
    from codegen.families.algebraic_uio import validation as algebraic
    b = builds[name]
    obs = load(name)
    f = b.step_function()
    rows = algebraic.periodic_inputs(b)[:400]
    state = obs.initial_state()
    out = np.empty(obs.n_output)
    nu, ny = b.nu, b.ny
    worst = 0.0
    for k, row in enumerate(rows):
        z = state.copy()
        cas = np.asarray(f(z, row[:nu], row[nu:nu + ny], row[nu + ny:])[0]).ravel()
        ref, excess, warm = b.step_numpy(z, row[:nu], row[nu:nu + ny], row[nu + ny:])
        status = obs.step(state, row, out)
        np.testing.assert_array_equal(state, cas)          # the C is CasADi's own code: bit-identical
        assert status == (obs.status_bits["WARMING_UP"] if k == 0 else 0)
        assert (warm == 1.0) == (k == 0) and excess == 0.0
        np.testing.assert_array_equal(out, state[-obs.n_output:])
        worst = max(worst, float(np.abs(state - ref).max() / max(np.abs(ref).max(), 1.0)))
    assert worst < 1e-9


@pytest.mark.slow          # the compiled observers
def test_c_step_status_behaviour():
    from python_bindings import load
    obs = load("algebraic_uio_example2")
    bits = obs.status_bits
    s, out = obs.initial_state(), np.empty(obs.n_output)
    assert obs.step(s, np.array([0.1, 3.0]), out) == bits["WARMING_UP"]
    assert obs.step(s, np.array([0.1, 3.0]), out) == 0
    held = s.copy()
    assert obs.step(s, np.array([np.nan, 3.0]), out) == bits["NONFINITE_INPUT"]
    np.testing.assert_array_equal(s, held)
    assert obs.step(s, np.array([0.1, 7.0]), out) & bits["SCHEDULING_CLAMPED"]
    assert np.isfinite(s).all()


# ---- item 4: the examples' targets ----------------------------------------------------------------------

@pytest.mark.slow          # the compiled observers
@pytest.mark.parametrize("name", ["algebraic_uio_example1", "algebraic_uio_example2"])
def test_noise_free_examples_reach_1e_6(name):
    """State and UI errors below 1e-6 of each signal's peak once the differentiators have converged and
    the certified decay has shrunk the initial error by 1e6 (t >= t_c + T_obs); compiled C step."""
    from codegen.validation import run as validate
    res = validate.run_scenario(name, "paper")
    assert res["status_flags"] == 0
    conv = res["differentiator_convergence"]
    assert conv["t_c"] < 3.0
    windows = res["paper_format"]["rows"]
    for sig, row in windows.items():
        assert row["max_rel_after_t_c_plus_T_obs"] < 1e-6, (sig, row)
        # the one definition of every validation beside the family's windows: the unknown input is
        # dimensionless, the states (normalized time) declare no unit
        assert res["observer"][sig]["unit"] == ("1" if sig == "d" else None), (sig, res["observer"][sig]["unit"])
        assert res["observer"][sig]["samples"] > 0
    if name == "algebraic_uio_example2":       # here already right after t_c
        assert all(row["max_rel_after_t_c"] < 1e-6 for row in windows.values())


@pytest.mark.slow          # the compiled observers
def test_lateral_force_with_noise_meets_5_percent():
    from codegen.validation import run as validate
    res = validate.run_scenario("algebraic_uio_lateral_force", "paper")
    assert res["status_flags"] == 0 and res["noise"] == {"v_y": 0.01}
    assert res["paper_format"]["rows"]["F_yr"]["rms_percent_after_5s"] <= 5.0
    assert res["observer"]["F_yr"]["unit"] == "N" and res["observer"]["F_yr"]["rms_percent"] <= 5.0
    assert res["max_abs_ay"] > 5.0          # the tyres are in their nonlinear range (xi != 0)


# ---- issue 42 item 10: advice of a decay rate that is allowed and works, or of a sensor -----------------

def _yaw_moment_build(tmp_path, outputs, alpha=1.0):
    """A relative-degree-2 yaw-moment model: heading psi' = r, yaw rate r' = -(c / v) r + M_z / I_z
    (the yaw moment M_z unknown, the damping falling with the speed v), lateral offset e' = V psi at a
    reference speed V. With the heading alone the offset is an unobservable integrator: a fixed mode
    at 0 of A - Q Mcal."""
    psi, r, e, M_z = sp.symbols("psi r e M_z")
    v = sp.Symbol("v", positive=True)
    states = {"psi": psi, "r": r, "e": e}
    model = ModelDefinition("yaw_moment", (psi, r, e), (), (M_z,),
                            sp.Matrix([r, -40.0 * r / v + M_z / 2500.0, 20.0 * psi]),
                            tuple((o, states[o]) for o in outputs), (SchedulingSignal(v),), ())
    params = _write_params(tmp_path, "yaw", sched="v", lo=5.0, hi=30.0,
                           extra="derivative_bounds = [[-1.0, 1.0]]\n\n[state_bounds]\npsi = [-0.5, 0.5]\nr = [-1.0, 1.0]\ne = [-2.0, 2.0]\n")
    spec = {"order": 5, "lipschitz": 1e3}
    cfg = ObserverConfig("yaw_test", "algebraic_uio", "none", "yaw.toml", "", "exact", 0.001,
                         {"lmi": "direct", "alpha": alpha, "margin": 1e-4,
                          "differentiators": {**{f"y_{o}": spec for o in outputs}, "v": {"order": 5, "lipschitz": 50.0}}},
                         {}, "", str(tmp_path / "yaw.toml"))
    return algebraic_uio.build(cfg, FreshSolver(), lpv=instantiate(model, params))


def test_no_decay_rate_works_for_a_mode_that_does_not_decay_and_the_sensor_named_does(tmp_path):
    """The error said "choose alpha < -0" (or "< -2.447") where alpha > 0 is required: no alpha works
    for a fixed mode that does not decay. It says so and names the state to measure; measured, the
    design goes through."""
    (tmp_path / "yaw.toml").write_text("")
    with pytest.raises(InfeasibleLMIError) as err:
        _yaw_moment_build(tmp_path, ("psi",))
    text = str(err.value)
    assert "no [design] alpha (> 0) works" in text and "choose" not in text, text
    assert "measure e too" in text, text
    b = _yaw_moment_build(tmp_path, ("psi", "e"))
    assert b.dec.relative_degrees == (2, 3) and b.design.fixed_modes["count"] == 0


def test_a_decay_rate_below_the_fixed_modes_that_the_error_advises_designs(builds):
    """Example 1, alpha = 6.5 beyond its fixed mode at -6: the advised value, applied, designs."""
    b = builds["algebraic_uio_example1"]
    with pytest.raises(InfeasibleLMIError) as err:
        alg.design(b.dec, dataclasses.replace(b.settings, alpha=6.5), FreshSolver())
    import re
    advised = float(re.search(r"choose \[design\] alpha < 6 \(e\.g\. ([0-9.]+)\)", str(err.value)).group(1))
    assert 0 < advised < 6
    alg.design(b.dec, dataclasses.replace(b.settings, alpha=advised), FreshSolver())
