"""Derived known inputs (functions of the measurements computed inside the step) and the
CommonRoad twin's model that uses them: camber terms and the tyres' nonlinear remainders."""
import math
import tomllib

import numpy as np
import pytest
import sympy as sp

from codegen.validation import simulate
from codegen.families.linf_uio import discrete
from codegen.validation import common
from codegen.errors import ModelDefinitionError, NotAffineError
from codegen.model import (DerivedInput, ModelDefinition, ParameterSet, SchedulingBox, SchedulingSignal,
                           instantiate)

NAME = "lpv_linf_driver_torque_bmw320i"


def _toy(w_expr):
    x, u, d, v, k, w = sp.symbols("x u d v k w")
    return ModelDefinition("toy", (x,), (u,), (d,), sp.Matrix([-k * v * x + u + 2 * w + d]), (("x", x),),
                           (SchedulingSignal(v),), (k,), derived_inputs=(DerivedInput(w, w_expr),))


def test_derived_input_may_only_use_measurements():
    x = sp.Symbol("x")
    with pytest.raises(ModelDefinitionError, match="derived input w uses x"):
        _toy(x ** 2)
    with pytest.raises(ModelDefinitionError, match="must hold DerivedInput"):
        ModelDefinition("bad", (x,), (), (), sp.Matrix([-x]), (("x", x),), (), (), derived_inputs=(x,))


def test_derived_input_matrices_and_step():
    m = _toy(sp.Symbol("y_x") ** 2 * sp.Symbol("v"))
    params = ParameterSet("toy", {"k": 1.0}, {"v": SchedulingBox("v", 1.0, 2.0, -1.0, 1.0)}, {})
    lpv = instantiate(m, params)
    assert lpv.Bw == sp.Matrix([[2]]) and lpv.B == sp.Matrix([[1]]) and lpv.Duw.shape == (1, 1)
    assert [str(s) for s, _ in lpv.derived_inputs] == ["w"]
    w = sp.Symbol("w")
    with pytest.raises(NotAffineError, match="derived inputs"):
        x, u, d, v = sp.symbols("x u d v")
        bad = ModelDefinition("bad", (x,), (u,), (d,), sp.Matrix([-v * x + w ** 2 + u + d]), (("x", x),),
                              (SchedulingSignal(v),), (), derived_inputs=(DerivedInput(w, sp.Symbol("y_x")),))
        instantiate(bad, ParameterSet("bad", {}, {"v": SchedulingBox("v", 1.0, 2.0, -1.0, 1.0)}, {}))


@pytest.fixture(scope="module")
def bmw(built):
    return built(NAME)


def test_bmw_twin_inputs_are_the_seeds(bmw):
    """The camber/remainder terms are computed inside the step: the caller passes what the paper's does."""
    assert bmw.input_names == ["T_a", "y_r", "y_delta", "y_delta_dot", "v_x"]
    assert [str(s) for s, _ in bmw.lpv.derived_inputs] == ["s_c", "F_nf", "F_nr", "T_nl"]
    assert bmw.poly.n_vertices == 2 and bmw.poly.Bw.shape == (2, 4, 4)
    assert bmw.discrete_certificate.kappa > 1


@pytest.mark.slow          # the compiled extension
def test_compiled_step_equals_numpy_step_with_derived_inputs(bmw):
    from python_bindings import load
    obs = load(NAME)
    lpv = bmw.lpv
    scn = common.scenario_for(bmw.config, "takeover_opposing_assist", duration=4.0)
    truth = simulate.nominal_plant(bmw.config, lpv, scn)
    inputs = simulate.observer_input_matrix(obs.input_names, truth,
                                            simulate.add_sensor_noise(truth, common.SENSOR_NOISE, seed=1))
    out, status, _ = obs.run(inputs)
    assert not status.any()
    z = np.zeros(obs.n_state)
    nu, ny = lpv.nu, lpv.ny
    for k in range(inputs.shape[0]):
        z, flag = discrete.step_numpy(bmw.data, z, inputs[k, :nu], inputs[k, nu:nu + ny], inputs[k, nu + ny:])
        assert flag == 0.0
        assert np.allclose(out[k], z, rtol=1e-9, atol=1e-12)
    assert np.abs(out[:, -1]).max() > 0.5          # the driver torque is being estimated


# --- the remainder functions against the plant's own tyre and trail model --------------------

@pytest.fixture(scope="module")
def cr():
    pytest.importorskip("vehiclemodels")
    from codegen.validation import commonroad_plant as C
    from model_defs import steering_single_track_camber as M
    values = tomllib.loads(C.params_toml(2))["parameters"]
    subs = {p: values[str(p)] for p in M.MODEL.parameters}
    return C, M, values, subs


def test_slip_inversion_matches_pac2002(cr):
    from vehiclemodels.utils import tire_model
    C, M, values, subs = cr
    pv = C.vehicle_parameters(2)
    u = sp.Symbol("u")
    inverse = sp.lambdify(u, M.slip_of_utilization(u, M.C_f, M.F_zf).subs(subs), "math")
    fz = values["F_zf"] / 2
    for alpha in (1e-4, 0.005, 0.02, 0.05, 0.09):
        force = tire_model.formula_lateral(-alpha, 0.0, fz, pv.tire)[0]      # the package's alpha is -alpha
        assert inverse(force / (pv.tire.p_dy1 * fz)) == pytest.approx(alpha, rel=1e-6)   # 2 fixed-point steps in E


def test_remainders_close_the_plant_aligning_torque_and_force(cr):
    """At the slip a measured lateral acceleration implies, linear part + remainder = the plant's
    PAC2002 axle force and its trail-based aligning torque (codegen.validation.commonroad_plant)."""
    from vehiclemodels.utils import tire_model
    C, M, values, subs = cr
    pv = C.vehicle_parameters(2)
    col = C.TABLE1_COLUMN
    v_x, y_r = M.v_x, M.y_r
    f_nf = sp.lambdify((y_r, v_x), M.F_nf_expr.subs(subs), "math")
    t_nl = sp.lambdify((y_r, v_x), M.T_nl_expr.subs(subs), "math")
    L = values["l_f"] + values["l_r"]
    share = values["M"] * values["l_r"] / L - values["k_f"]
    tan_sl = 3 * abs(pv.tire.p_dy1) / abs(pv.tire.p_ky1)
    fz = values["F_zf"] / 2
    for alpha in (0.003, 0.01, 0.02, 0.04):
        pure = 2 * tire_model.formula_lateral(-alpha, 0.0, fz, pv.tire)[0]              # axle, both tyres
        q = (pure + values["F_cf"]) / share                                             # |q| > a_s here
        vx = 20.0
        linear_force = 2 * values["C_f"] * alpha
        assert linear_force + f_nf(q / vx, vx) == pytest.approx(pure, rel=1e-6)
        t_al_plant = -col.K_p * C.pneumatic_trail(alpha, col.eta_t, tan_sl) * pure / col.R_s
        t_al_linear = -col.K_p * col.eta_t * linear_force / col.R_s
        assert t_al_linear + t_nl(q / vx, vx) == pytest.approx(t_al_plant, rel=1e-6)
        # odd in the lateral acceleration
        assert t_nl(-q / vx, vx) == pytest.approx(-t_nl(q / vx, vx), rel=1e-12)
    assert t_nl(0.0, 20.0) == 0.0 and f_nf(0.0, 20.0) == 0.0
    # finite for any finite (even overflowing) measurement
    assert all(math.isfinite(f(1e308, 35.0)) for f in (f_nf, t_nl))


# -- constant terms: a known input of value 1 (issue 42, item 5) ---------------------------------------
def _rolling(params_values=None):
    """v' = u / m - f_r g - c v_x^2 / m + d: rolling resistance (a constant) and drag (of the scheduling); an
    output that reads the state (an output of no state is refused) beside the constant."""
    x, u, d, v_x = sp.symbols("x u d v_x")
    m, f_r, g, c = sp.symbols("m f_r g c", positive=True)
    model = ModelDefinition("rolling", (x,), (u,), (d,), sp.Matrix([-x / v_x + u / m - f_r * g - c * v_x ** 2 / m + d]),
                            (("x", x), ("a", u / m - f_r * g - x / v_x)), (SchedulingSignal(v_x),), (m, f_r, g, c))
    params = ParameterSet("rolling.toml", params_values or {"m": 1000.0, "f_r": 0.015, "g": 9.81, "c": 0.4},
                          {"v_x": SchedulingBox("v_x", 5.0, 40.0, -1.0, 1.0)}, {})
    return model, params


def test_a_constant_term_is_a_known_input_of_value_one():
    """A term free of states and inputs (rolling resistance -f_r g, a drag of the scheduling signal) was
    refused ("a drift term independent of states and inputs"): it is the column of a derived input
    ``one`` of value 1, in the dynamics and the outputs, and the equations are the model's where one = 1."""
    model, params = _rolling()
    lpv = instantiate(model, params)
    v_x = sp.Symbol("v_x")
    assert [(str(s), e) for s, e in lpv.derived_inputs] == [("one", 1)]
    assert sp.simplify(lpv.Bw[0, 0] - (-0.015 * 9.81 - 0.4 * v_x ** 2 / 1000.0)) == 0
    assert sp.simplify(lpv.Duw[1, 0] + 0.015 * 9.81) == 0 and lpv.Duw[0, 0] == 0
    assert lpv.A == sp.Matrix([[-1 / v_x]]) and lpv.B == sp.Matrix([[1 / 1000.0]])
    one = sp.Symbol("one")
    for new, old in zip((*lpv.definition.dynamics, *(e for _, e in lpv.definition.outputs)),
                        (*model.dynamics, *(e for _, e in model.outputs))):
        assert sp.simplify(sp.sympify(new).subs(one, 1) - old) == 0
    # the sector polytope carries it: Bw at each vertex is the term at that vertex's v_x
    from codegen.representation import polytope
    poly = polytope.sector_polytope(lpv)
    assert poly.Bw.shape[-1] == 1


def test_a_constant_term_takes_a_name_the_model_does_not_use():
    x, one, d = sp.symbols("x one d")
    model = ModelDefinition("named", (x,), (one,), (d,), sp.Matrix([-x + one + 3 + d]), (("x", x),), (), ())
    lpv = instantiate(model, ParameterSet("p", {}, {}, {}))
    assert [str(s) for s, _ in lpv.derived_inputs] == ["one_w"] and lpv.Bw == sp.Matrix([[3]])


def test_a_family_without_known_inputs_of_its_own_names_the_one_that_takes_constant_terms():
    """A family whose step has no derived input refuses a constant term by one typed line naming the
    term and the family that takes it (not a "derived input" the user never wrote)."""
    model, params = _rolling()
    lpv = instantiate(model, params)
    with pytest.raises(NotAffineError, match=r"terms independent of the states and inputs \(dx/dt: -0\.0004\*v_x\*\*2 "
                                             r"- 0\.14715: a known input of value 1\); the switched observer takes "
                                             r"no such input \(its paper\)\. The L-infinity UIO \(family \w+\) takes "
                                             r"them"):
        lpv.require_no_derived_inputs("switched observer", "its paper")
