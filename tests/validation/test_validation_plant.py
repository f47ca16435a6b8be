"""CommonRoad multi-body plant driven by the Nguyen et al. 2019 steering column, and the scenario library."""
import tomllib

import numpy as np
import pytest

pytest.importorskip("vehiclemodels", reason="commonroad-vehicle-models not installed")

from codegen.errors import ModelDefinitionError, SampleError  # noqa: E402
from codegen.validation import commonroad_plant as C  # noqa: E402
from codegen.validation import scenarios as S  # noqa: E402

ROOT = next(p for p in __import__("pathlib").Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
TABLE1 = ROOT / "model_defs" / "params" / "nguyen2019_table1.toml"


@pytest.fixture(scope="module")
def circle():
    sc = S.steady_circle(radius=60.0, speed=12.0, duration=8.0)
    return sc, C.simulate(sc)


def test_straight_run_keeps_beta_zero():
    gt = C.simulate(S.straight_line(speed=20.0, duration=3.0))
    assert gt.t.size == 301 and gt.t[-1] == pytest.approx(3.0)
    # hands off: only the PAC2002 camber-shift terms (p_hy*, p_vy*) pull the car slightly
    assert np.degrees(np.abs(gt.beta).max()) < 0.1
    assert np.abs(gt.a_y).max() < 0.5
    assert np.abs(gt.v_x - 20.0).max() < 0.05
    assert np.all(gt.T_d == 0) and np.all(gt.T_a == 0)


def test_steady_circle_consistent(circle):
    sc, gt = circle
    last = slice(-100, None)                      # last second
    vx, r, ay, beta = (gt.v_x[last].mean(), gt.r[last].mean(), gt.a_y[last].mean(),
                       gt.beta[last].mean())
    assert vx == pytest.approx(12.0, abs=0.05)
    assert r == pytest.approx(12.0 / 60.0, rel=0.01)          # path held
    assert ay == pytest.approx(vx * r, rel=0.005)             # steady: a_y = v_x r (+ v̇_y ≈ 0)
    assert ay < 4.0                                           # linear range
    # linear single-track steady-state sideslip with the derived parameters
    params = tomllib.loads(C.params_toml(2))["parameters"]
    L = params["l_f"] + params["l_r"]
    beta_lin = params["l_r"] / 60.0 - params["M"] * params["l_f"] * vx ** 2 / (2 * params["C_r"] * L * 60.0)
    assert beta == pytest.approx(beta_lin, rel=0.2)
    assert beta > 0                                           # left turn at low speed
    assert np.ptp(gt.beta[last]) < 1e-3


def test_column_torque_balance(circle):
    sc, gt = circle
    col = C.TABLE1_COLUMN
    # the column ODE holds along the trajectory (finite-difference δ̈)
    dd = np.gradient(gt.delta_dot, gt.t)
    resid = col.I_s * col.R_s * dd - (gt.T_d + gt.T_a + gt.T_al - col.B_s * col.R_s * gt.delta_dot)
    assert np.abs(resid[10:]).max() < 0.05 * np.abs(gt.T_d).max()
    # steady state: the driver holds the aligning torque, which restores (opposes the turn)
    last = slice(-100, None)
    assert gt.T_d[last].mean() == pytest.approx(-gt.T_al[last].mean(), abs=0.05)
    assert gt.T_al[last].mean() < 0 < gt.T_d[last].mean()
    # and its size matches K_p η_t F_yf / R_s with F_yf = m a_y l_r / L (trail falls a little)
    p = tomllib.loads(C.params_toml(2))["parameters"]
    fyf = p["M"] * gt.a_y[last].mean() * p["l_r"] / (p["l_f"] + p["l_r"])
    lin = col.K_p * col.eta_t * fyf / col.R_s
    assert 0.6 * lin < gt.T_d[last].mean() < 1.05 * lin
    assert 1.0 < gt.T_d[last].mean() < 10.0                   # a few N m


def test_params_toml_format_and_slope(tmp_path):
    from codegen.model import definition as model
    from model_defs.steering_single_track_camber import MODEL
    text = C.params_toml(2)
    data = tomllib.loads(text)
    ref = tomllib.loads(TABLE1.read_text())
    assert set(data["parameters"]) == {str(p) for p in MODEL.parameters}
    assert set(ref["parameters"]) <= set(data["parameters"])           # the paper's names, plus camber/tyre
    assert data["scheduling"] == ref["scheduling"]
    for k in ("eta_t", "R_s", "B_s", "K_p", "I_s"):
        assert data["parameters"][k] == ref["parameters"][k]
    pv = C.vehicle_parameters(2)
    fzf, fzr = C._static_loads(pv)
    assert data["parameters"]["C_f"] == pytest.approx(abs(pv.tire.p_ky1) * fzf, rel=1e-6)
    assert data["parameters"]["C_r"] == pytest.approx(abs(pv.tire.p_ky1) * fzr, rel=1e-6)
    assert data["parameters"]["M"] == pv.m and data["parameters"]["l_f"] == pv.a
    assert data["parameters"]["F_zf"] == pytest.approx(2 * fzf) and data["parameters"]["mu_y"] == pv.tire.p_dy1
    f = tmp_path / "cr2.toml"
    f.write_text(text)
    lpv = model.instantiate(MODEL, model.load_parameters(f))   # the toolchain accepts it
    assert lpv.nx == 4 and len(lpv.derived_inputs) == 4


def test_camber_coefficients_are_the_tyre_functions():
    """c0 + c1 |gamma| is what the package's formula_lateral adds at zero slip, gamma against the turn."""
    from vehiclemodels.utils import tire_model
    pv = C.vehicle_parameters(2)
    c0, c1 = C.camber_force_coefficients(pv.tire)
    fz = 3000.0
    for gamma in (-1e-6, -0.01, -0.04):
        added = tire_model.formula_lateral(0.0, gamma, fz, pv.tire)[0] - tire_model.formula_lateral(0.0, 0.0, fz, pv.tire)[0]
        assert added == pytest.approx(fz * (c0 + c1 * abs(gamma)), rel=1e-2)   # small-slip linearization
    assert 0.015 < c0 < 0.03 and 0.8 < c1 < 1.2


def test_roll_camber_matches_the_multibody_steady_roll(circle):
    """The quasi-static roll/camber formula against the plant's own steady state on a circle."""
    sc, gt = circle
    last = slice(-100, None)
    rc = C.roll_camber(C.vehicle_parameters(2))
    roll, ay = gt.roll[last].mean(), gt.a_y[last].mean()
    assert roll < 0 < ay                                                      # rolls out of the turn
    assert -roll / ay == pytest.approx(rc.roll_gradient, rel=0.03)
    assert gt.camber_f[last].mean() / roll == pytest.approx(rc.camber_per_roll_f, rel=0.03)


def test_camber_model_reproduces_the_plant_steady_state(circle):
    """From the measured r and v_x alone, the observer's model predicts the plant's steady sideslip,
    steering angle and aligning torque; the paper's linear model misses the aligning torque by 30 %."""
    import sympy as sp
    from model_defs import steering_single_track, steering_single_track_camber
    sc, gt = circle
    last = slice(-100, None)
    r, vx = gt.r[last].mean(), gt.v_x[last].mean()
    values = tomllib.loads(C.params_toml(2))["parameters"]
    b, d, T_d = sp.symbols("beta delta T_d")
    predicted = {}
    for m in (steering_single_track.MODEL, steering_single_track_camber.MODEL):
        subs = {p: values[str(p)] for p in m.parameters}
        v_sym = sp.Symbol("v_x", positive=True)
        w = {g.symbol: sp.sympify(g.expr).subs(subs).subs({sp.Symbol("y_r"): r, v_sym: vx}) for g in m.derived_inputs}
        f = m.dynamics.subs(subs).subs(w).subs({sp.Symbol("r"): r, v_sym: vx, sp.Symbol("delta_dot"): 0,
                                               sp.Symbol("T_a"): 0})
        sol = sp.solve([f[0], f[1]], [b, d], dict=True)[0]
        t_d = sp.solve(f[3].subs(sol), T_d)[0]           # the driver holds the column still
        predicted[m.name] = (float(sol[b]), float(sol[d]), -float(t_d))
    beta_c, delta_c, t_al_c = predicted["steering_single_track_camber"]
    assert np.degrees(beta_c) == pytest.approx(np.degrees(gt.beta[last].mean()), abs=0.02)
    assert np.degrees(delta_c) == pytest.approx(np.degrees(gt.delta[last].mean()), abs=0.01)
    assert t_al_c == pytest.approx(gt.T_al[last].mean(), abs=0.15)
    t_al_lin = predicted["steering_single_track"][2]
    assert abs(t_al_lin - gt.T_al[last].mean()) > 1.0


def test_plant_config_errors():
    with pytest.raises(ModelDefinitionError):
        C.PlantConfig(vehicle=7)
    with pytest.raises(ModelDefinitionError):
        C.PlantConfig(dt_internal=0.003)
    with pytest.raises(ModelDefinitionError):
        C.ColumnParams(I_s=0.0)
    with pytest.raises(SampleError):
        C.simulate(S.straight_line(sample_rate=50.0))


@pytest.mark.parametrize("name", S.names())
def test_scenarios_reproducible(name):
    a, b = S.make(name), S.make(name)
    assert a.arrays().keys() == b.arrays().keys()
    for k, v in a.arrays().items():
        assert np.array_equal(v, b.arrays()[k]), k
        assert np.all(np.isfinite(v))
    assert a.t[0] == 0 and np.allclose(np.diff(a.t), 0.01)
    assert 5.0 <= a.v_ref.min() and a.v_ref.max() <= 35.0
    assert np.abs(a.a_ref).max() <= 4.5
    assert np.abs(a.T_a).max() <= 3.0
    # open-loop human torque component: a few tenths of N m, 0.1-5 Hz content
    assert 0.1 <= np.sqrt(np.mean(a.T_d_open ** 2)) <= 1.0
    spec = np.abs(np.fft.rfft(a.T_d_open)) ** 2
    f = np.fft.rfftfreq(a.t.size, 0.01)
    assert spec[(f >= 0.05) & (f <= 6.0)].sum() > 0.95 * spec.sum()


def test_seeds_change_the_random_parts():
    a, b = S.make("track_varying_speed"), S.make("track_varying_speed", seed=99)
    assert not np.array_equal(a.T_d_open, b.T_d_open)
    assert not np.array_equal(a.v_ref, b.v_ref)


def test_scenario_specifics():
    z = S.make("zigzag_growing_ay")
    ay_ref = np.abs(z.kappa_ref * z.v_ref ** 2)
    assert 7.5 <= ay_ref.max() <= 8.5 and ay_ref[: 1000].max() < 3.0
    assert np.all(S.make("zigzag_constant_speed_assist").v_ref == 15.0)
    tk = S.make("takeover_opposing_assist")
    assert np.all(tk.v_ref == 14.0)
    turn = np.abs(tk.kappa_ref) > 1e-4
    assert np.mean(np.sign(tk.T_a[turn]) == -np.sign(tk.kappa_ref[turn])) > 0.9   # opposing
    acc = S.make("random_trajectory_accel")
    assert np.all(acc.a_ref[acc.t < 13.9] == 0) and acc.a_ref[(acc.t > 15) & (acc.t < 23)].min() > 1.0
    g = S.make("time_varying_grip")
    assert np.all((1 / g.kappa_ref >= 44.99) & (1 / g.kappa_ref <= 55.01))
    assert g.friction(0.0, 0.0, 0.0) == pytest.approx(0.6)
    assert g.friction(0.0, 0.7, 0.0) == pytest.approx(1.2)            # sin(π/2) with l_r = 1.4
    assert g.friction(0.0, 2.1, 0.0) == pytest.approx(0.05)           # floored
    gn = S.make("time_varying_grip_normal")                            # Nguyen et al. 2021 scenario 3
    assert np.all((1 / gn.kappa_ref >= 44.99) & (1 / gn.kappa_ref <= 55.01))
    assert gn.v_ref[0] == 6.0 and gn.v_ref[-1] == 9.0 and np.all(np.diff(gn.v_ref) >= 0)   # increasing
    assert gn.friction(0.0, 0.745, 0.0) == pytest.approx(1.2)           # sin(π/2) with Table I's l_r = 1.49
    assert gn.friction(0.0, 0.0, 2.235) == pytest.approx(0.05)          # sin(3π/2), floored
    assert S.make("circular_path").circle == (0.0, 40.0, 40.0)


def test_scenario_errors():
    with pytest.raises(S.ScenarioError, match="unknown scenario"):
        S.make("nope")
    with pytest.raises(ModelDefinitionError):
        S.make("circular_path", seed=-1)
    with pytest.raises(S.ScenarioError):
        S.make("circular_path", sample_rate=0)
    with pytest.raises(AttributeError):
        S.make("circular_path").seed = 3                                # frozen
