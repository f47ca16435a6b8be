"""Nguyen et al. 2021: TS form derived from the model, sound Jacobian bounds, design, certificates, C step."""
import dataclasses

import numpy as np
import pytest
import sympy as sp

from codegen.representation import bounds
from codegen.project import observer_file as observers
from codegen import pipeline
from codegen.families.ts_fuzzy_uio import representation as ts_fuzzy
from codegen.families.ts_fuzzy_uio import design as ts_fuzzy_uio
from codegen.errors import RankConditionError, SchedulingBoundsError, ModelDefinitionError
from codegen.model import ModelDefinition, load_parameters
from codegen.families.ts_fuzzy_uio import validation as ts_validation
from codegen.validation import common

NAME = "ts_fuzzy_uio"


@pytest.fixture(scope="module")
def tsb(built):
    return built(NAME)


@pytest.fixture(scope="module")
def compiled():
    from python_bindings import load
    return load(NAME)


def test_split_finds_the_seeds_premises_and_consequent(tsb):
    ts = tsb.ts
    vx, vy, r = ts.definition.states
    assert [p.expr for p in ts.premises] == [1 / vx, r]            # xi = [1/v_x, r] of eq. (8)
    assert ts.phi == (vy ** 2,)                                     # unmeasured consequent
    assert ts.measured == (vx, r) and ts.unmeasured == (vy,)
    assert ts.n_rules == 4
    np.testing.assert_allclose(ts.G[0].ravel(), [0.0, -0.01 * 0.45 / 1476.0, 0.0], rtol=1e-12)
    # A_1 = A(lower 1/v_x, lower r): row 1 of (8), a_22 = -2(C_f + C_r)/(M v_x), Euler at 0.01 s
    p = ts.parameters.values
    assert ts.A[0][1, 1] == pytest.approx(1 - 0.01 * 2 * (p["C_f"] + p["C_r"]) / (p["M"] * 30.0), rel=1e-12)
    assert ts.A[0][0, 1] == pytest.approx(0.01 * -0.55) and ts.A[1][0, 1] == pytest.approx(0.01 * 0.55)


def test_ts_model_reproduces_the_euler_model_exactly(tsb):
    """sum h_i A_i x + D d + f + G phi equals x + Ts F(x, d) of eq. (1)/(3) everywhere in D_x."""
    ts = tsb.ts
    d = ts.definition
    subs = {s: ts.parameters.values[str(s)] for s in d.parameters}
    F = sp.lambdify([*d.states, *d.unknown_inputs], sp.Matrix(d.dynamics).subs(subs), "numpy")
    f = sp.lambdify(ts.measured, ts.f, "numpy")
    rng = np.random.default_rng(1)
    for _ in range(200):
        x = np.array([rng.uniform(*ts.state_box[s]) for s in d.states])
        dd = rng.normal(size=2) * [300.0, 0.05]
        h = ts.h(x[[0, 2]])
        assert h.sum() == pytest.approx(1.0, abs=1e-14) and (h >= -1e-15).all()
        lhs = sum(w * a for w, a in zip(h, ts.A)) @ x + ts.D @ dd + np.asarray(f(x[0], x[2]), float).ravel() \
            + sum(w * g for w, g in zip(h, ts.G)) @ np.array([x[1] ** 2])
        rhs = x + 0.01 * np.asarray(F(*x, *dd), float).ravel()
        np.testing.assert_allclose(lhs, rhs, rtol=1e-12, atol=1e-12)


def test_seed_membership_h4_typo_breaks_the_convex_sum(tsb):
    """Eq. (11) prints h4 = Omega_v1 Omega_r1; ours is Omega_v2 Omega_r2 and sums to one."""
    ts = tsb.ts
    (p_v, p_r) = ts.premises
    V, R = np.meshgrid(np.linspace(p_v.lower, p_v.upper, 51), np.linspace(p_r.lower, p_r.upper, 51))
    Ov1, Ov2 = (p_v.upper - V) / (p_v.upper - p_v.lower), (V - p_v.lower) / (p_v.upper - p_v.lower)
    Or1, Or2 = (p_r.upper - R) / (p_r.upper - p_r.lower), (R - p_r.lower) / (p_r.upper - p_r.lower)
    printed = Ov1 * Or1 + Ov1 * Or2 + Ov2 * Or1 + Ov1 * Or1
    assert np.abs(printed - 1).max() > 0.5
    hs = np.array([ts.h([1 / v, r]) for v, r in zip(V.ravel(), R.ravel())])
    np.testing.assert_allclose(hs.sum(axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(hs[:, 3], (Ov2 * Or2).ravel(), atol=1e-14)


def test_jacobian_bounds_are_sound_and_tight(tsb):
    """Sampled values inside the bounds; bounds within 1 % of the sampled extremes."""
    ts = tsb.ts
    rng = np.random.default_rng(7)
    for phi, row in zip(ts.phi, ts.jacobian_bounds):
        for s, b in zip(ts.definition.states, row):
            dphi = sp.diff(phi, s)
            if dphi == 0:
                assert b.lower == b.upper == 0.0
                continue
            fn = sp.lambdify(ts.definition.states, dphi, "numpy")
            grid = [np.linspace(*ts.state_box[v], 41) for v in ts.definition.states]
            pts = np.stack(np.meshgrid(*grid, indexing="ij"), -1).reshape(-1, 3)
            pts = np.vstack([pts, np.column_stack([rng.uniform(*ts.state_box[v], 100000) for v in ts.definition.states])])
            vals = np.broadcast_to(fn(*pts.T), (pts.shape[0],))
            assert b.lower <= vals.min() and vals.max() <= b.upper
            span = vals.max() - vals.min()
            assert vals.min() - b.lower <= 0.01 * span and b.upper - vals.max() <= 0.01 * span
    assert ts.theta_vertices.shape == (2, 1, 3)       # zero-width entries collapsed


def test_interval_bounds_on_a_harder_function():
    x, y = sp.symbols("x y")
    expr = sp.sin(x) * y ** 2 - x / (1 + y ** 2) + sp.atan(x * y)
    box = {x: (-1.0, 2.0), y: (-1.5, 1.5)}
    rb = bounds.range_bound(expr, box, rel_tol=1e-3)
    fn = sp.lambdify((x, y), expr, "numpy")
    X, Y = np.meshgrid(np.linspace(-1, 2, 601), np.linspace(-1.5, 1.5, 601))
    v = fn(X, Y)
    assert rb.lower <= v.min() and v.max() <= rb.upper
    assert v.min() - rb.lower <= 0.01 * np.ptp(v) and rb.upper - v.max() <= 0.01 * np.ptp(v)
    with pytest.raises(bounds.BoundsError, match="containing 0"):
        bounds.range_bound(1 / x, box)


def test_rank_condition_failure_is_a_clear_error(tsb):
    bad = dataclasses.replace(tsb.ts, C=np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    with pytest.raises(RankConditionError, match=r"\(15a\)"):
        ts_fuzzy_uio.decoupling_matrices(bad)


def test_outputs_must_measure_states(tsb):
    d = tsb.ts.definition
    vx, vy, r = d.states
    m = ModelDefinition("bad", d.states, (), d.unknown_inputs, d.dynamics, (("s", vx + r),), (), d.parameters)
    with pytest.raises(ModelDefinitionError, match="not a state"):
        ts_fuzzy.build(m, tsb.ts.parameters, 0.01)


def test_missing_state_bounds_is_a_clear_error(tsb):
    params = tsb.ts.parameters
    p = dataclasses.replace(params, state_bounds={"v_x": (5.0, 30.0)})
    # every missing bound in one run, each with the table that declares it
    with pytest.raises(SchedulingBoundsError, match=r"v_y, r have no bound .* add v_y = \[min, max\] under "
                                                    r"\[state_bounds\]; r = \[min, max\] under \[state_bounds\]"):
        ts_fuzzy.build(tsb.ts.definition, p, 0.01)


def test_design_certificate_and_decoupling(tsb):
    d, ts = tsb.design, tsb.ts
    np.testing.assert_allclose(d.T @ ts.D, 0.0, atol=1e-15)
    np.testing.assert_allclose(d.T + d.N @ ts.C, np.eye(3), atol=1e-15)
    assert tsb.recheck["worst_min_eig"] > 0
    assert tsb.recheck["blocks"] == 4 + 2 * 4 * (4 + 12)      # P_i, and (27a)+(27b) per theta_p, l
    assert tsb.decrease["max_ratio"] < 1.0
    assert tsb.timings["representation_s"] + tsb.timings["design_s"] < 5.0
    # other sample times are derived, not hard-coded
    cfg = observers.get(NAME)
    other = pipeline.build(dataclasses.replace(cfg, sample_time=0.005))
    assert other.ts.A[0][1, 1] == pytest.approx(1 - 0.5 * (1 - ts.A[0][1, 1]), rel=1e-12)


@pytest.mark.slow          # the compiled observer
def test_c_step_matches_numpy_and_casadi(tsb, compiled):
    rng = np.random.default_rng(11)
    f = tsb.step_function()
    out = np.empty(compiled.n_output)
    worst = 0.0
    for _ in range(3000):
        z = np.concatenate([rng.normal(size=3) * [0.1, 0.5, 0.05], [rng.uniform(5, 30), rng.uniform(-0.5, 0.5), 1.0],
                            rng.normal(size=5)])
        y = np.array([rng.uniform(5, 30), rng.uniform(-0.5, 0.5)])
        ref, excess, warm = tsb.step_numpy(z, [], y)
        cas = np.asarray(f(z, np.zeros(0), y, np.zeros(0))[0]).ravel()
        s = z.copy()
        status = compiled.step(s, y, out)
        assert status == (compiled.status_bits["SCHEDULING_CLAMPED"] if excess > 0 else 0)
        np.testing.assert_array_equal(s, cas)          # C is CasADi's own code: bit-identical
        worst = max(worst, np.abs(s - ref).max() / np.abs(ref).max())
        np.testing.assert_array_equal(out, s[-5:])
    assert worst <= 1e-12


@pytest.mark.slow          # the compiled observer
def test_c_step_status_behaviour(compiled):
    bits = compiled.status_bits
    s, out = compiled.initial_state(), np.empty(compiled.n_output)
    assert compiled.step(s, np.array([20.0, 0.1]), out) == bits["WARMING_UP"]
    assert compiled.step(s, np.array([20.0, 0.1]), out) == 0
    held = s.copy()
    assert compiled.step(s, np.array([np.nan, 0.1]), out) == bits["NONFINITE_INPUT"]
    np.testing.assert_array_equal(s, held)
    np.testing.assert_array_equal(out, held[-5:])
    assert compiled.step(s, np.array([60.0, 0.1]), out) & bits["SCHEDULING_CLAMPED"]
    assert np.isfinite(s).all()


# Measured on the Pacejka plant (observer's own equations (1) with magic-formula tyres; NOT the paper's
# 15-DOF simulator): (MAE, RMSD) per signal; docs/families/ts_fuzzy_uio.md. Tolerance 15 % above.
PACEJKA_MEASURED = {
    "circular_path_normal": {"v_y": (5.14e-4, 4.26e-4), "delta": (4.06e-5, 2.40e-5), "T_eng": (0.0489, 0.0437)},
    "random_trajectory_accel": {"v_y": (7.84e-4, 1.60e-3), "delta": (4.99e-5, 6.77e-5), "T_eng": (0.0806, 0.125)},
}


@pytest.mark.slow          # the compiled observer
@pytest.mark.parametrize("scenario", ["circular_path_normal", "random_trajectory_accel"])
def test_seed004_targets_on_the_pacejka_plant(scenario):
    """Table II's MAE and RMSD of v_y, delta, T_eng at the measured figures (+15 %); every MAE is at or
    below the paper's, and so is the T_eng RMSD. The RMSDs of v_y (2x in scenario 2, 4x in 1) and of
    delta in scenario 2 (8x) are above the paper's: asserted at our figure, not the paper's."""
    from codegen.validation import run as validate
    from codegen.validation import logs
    res = validate.run_scenario(NAME, scenario, "nominal")
    seed = ts_validation.PAPER_TABLE_II[scenario]
    obs = res["paper_format"]["rows"]        # Table II: SI units, delta in rad
    for sig, (mae, rmsd) in PACEJKA_MEASURED[scenario].items():
        assert obs[sig]["MAE"] <= 1.15 * mae, sig
        assert obs[sig]["RMSD"] <= 1.15 * rmsd, sig
        assert obs[sig]["MAE"] <= seed[sig][0], sig          # the paper's MAE met
    assert obs["T_eng"]["RMSD"] <= seed["T_eng"][1]
    assert res["status_flags"] == 0


@pytest.mark.slow          # the compiled observer
def test_seed004_scenario3_on_the_pacejka_plant():
    """Nguyen et al. 2021 scenario 3 in its normal-driving reading (``time_varying_grip_normal``): the delta
    target is met; v_y and T_eng miss the issue's targets (README: rear-tyre saturation in the literal
    grip law's minima, which the linear tyres (3) cannot follow) and are held to regression bounds;
    the same drive at the law's mean grip, constant, meets every target."""
    from codegen.validation import run as validate
    from codegen.validation import logs
    cfg = observers.get(NAME)
    res = validate.run_scenario(NAME, "time_varying_grip_normal", "nominal")
    seed = ts_validation.PAPER_TABLE_II["time_varying_grip_normal"]
    obs, truth = res["paper_format"]["rows"], res["signals"]["truth"]
    assert res["status_flags"] == 0
    assert truth["v_x"].max() <= 9.01 and res["max_abs_ay"] < 4.0          # normal driving on the path
    assert truth["mu"].min() == pytest.approx(0.05) and truth["mu"].max() > 1.19   # the law's full range
    assert obs["delta"]["MAE"] <= 2 * seed["delta"][0]
    assert obs["v_y"]["MAE"] <= 1.15 * 0.0245 and obs["T_eng"]["MAE"] <= 1.15 * 1.78  # measured + 15 %
    # where the v_y error comes from: samples with grip < 0.4 (a third of them) carry most of it
    keep = truth["t"] >= common.SETTLE_TIME
    err = np.abs(res["signals"]["estimate"]["v_y"] - truth["v_y"])[keep]
    low = truth["mu"][keep] < 0.4
    assert low.mean() < 0.4 and err[low].sum() > 0.75 * err.sum()
    # the same drive at constant grip 0.6 (the law's mean): every target of the issue
    const = dataclasses.replace(common.scenario_for(cfg, "time_varying_grip_normal"),
                                name="time_varying_grip_normal_constant", grip=None, mu=0.6)
    obs = ts_validation.run(cfg, const)["paper_format"]["rows"]
    assert obs["v_y"]["MAE"] <= 2 * seed["v_y"][0] and obs["delta"]["MAE"] <= 2 * seed["delta"][0]
    assert obs["T_eng"]["MAE"] <= 1.0


def test_the_innovation_gain_never_acts(tsb):
    """C T = 0 and C N = I: the measured part of x_hat is y itself, so y - C x_hat = 0 and the gain
    L(h) of (28) multiplies zero; no design choice (decay, objective) changes an estimate."""
    np.testing.assert_allclose(tsb.ts.C @ tsb.design.T, 0.0, atol=1e-14)
    np.testing.assert_allclose(tsb.ts.C @ tsb.design.N, np.eye(2), atol=1e-14)


def test_commonroad_parameter_file_is_derived_from_the_package():
    from codegen.validation import commonroad_angle
    from pathlib import Path
    committed = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file()) / "model_defs" / "params" / "commonroad_bmw320i_ts.toml"
    assert committed.read_text() == commonroad_angle.ts_params_toml(2)


def test_commonroad_torque_truth_is_the_effective_torque_of_eq1():
    """On the multi-body plant, T_eng truth = I_e (v_dot_x - v_y r) over each interval, and it is the
    drive torque less the wheels' spin-up and the steered wheels' projection (exact split)."""
    from codegen.validation import commonroad_angle
    cfg = observers.get("ts_fuzzy_uio_bmw320i")
    scn = common.scenario_for(cfg, "circular_path_normal", 6.0)
    tr = commonroad_angle.simulate(scn, 2, 100.0)
    p = commonroad_angle.vehicle_parameters(2)
    i_e = p.m * p.R_w
    np.testing.assert_allclose(tr["T_eng"] + tr["T_wheels"] + tr["T_steer"], tr["T_drive"], atol=1e-9)
    # after the start transient, the interval mean agrees with a 10 ms trapezoid of v_y r to 0.05 N m
    keep = tr["t"] >= 2.0
    fd = i_e * (np.diff(tr["v_x"]) / 0.01 - 0.5 * (tr["v_y"][1:] * tr["r"][1:] + tr["v_y"][:-1] * tr["r"][:-1]))
    assert np.max(np.abs(fd - tr["T_eng"][:-1])[keep[:-1]]) < 0.05
    # cornering: the steered wheels' projection is R_w F_yf sin(delta), F_yf ~ m a_y l_r / L in steady
    # state (12 N m here, at 6 m/s on R = 40 m): within 5 % of that estimate
    est = p.R_w * p.m * tr["a_y"] * p.b / (p.a + p.b) * np.sin(tr["delta"])
    assert np.all(tr["T_steer"][keep] > 0)
    assert np.mean(tr["T_steer"][keep]) == pytest.approx(np.mean(est[keep]), rel=0.05)


# Measured on the CommonRoad multi-body plant (the headline, like for like with the paper's simulator):
# circular_path_normal, (MAE, RMSD); docs/families/ts_fuzzy_uio.md. Tolerance 15 % above.
COMMONROAD_MEASURED = {"v_y": (0.01063, 0.00224), "delta": (4.44e-4, 1.24e-4), "T_eng": (0.784, 0.273)}


@pytest.mark.slow          # the compiled observer
def test_commonroad_angle_steered_run():
    """The CommonRoad twin on the multi-body plant, scenario 2: MAE and RMSD of Table II at the measured
    figures (+15 %). The paper's T_eng MAE 0.733 N m is missed by 7 %, its T_eng RMSD 5.21 met; v_y
    (19x) and delta (4.6x) miss it, the cause measured by the next test. Against the old truth
    (drive torque m R_w a_x) the T_eng MAE is 20.6 N m, 19.3 of it the steered-wheel projection."""
    from codegen.validation import run as validate
    from codegen.validation import logs
    res = validate.run_scenario("ts_fuzzy_uio_bmw320i", "circular_path_normal", "commonroad")
    obs = res["paper_format"]["rows"]        # Table II: SI units, delta in rad
    seed = ts_validation.PAPER_TABLE_II["circular_path_normal"]
    assert res["status_flags"] == 0
    for sig, (mae, rmsd) in COMMONROAD_MEASURED.items():
        assert obs[sig]["MAE"] <= 1.15 * mae, sig
        assert obs[sig]["RMSD"] <= 1.15 * rmsd, sig
    assert obs["T_eng"]["RMSD"] <= seed["T_eng"][1]
    truths = {k.split(" (")[0]: v["mae"] for k, v in res["torque_truths"].items()}
    assert truths["drive torque m R_w a_x"] == pytest.approx(20.6, rel=0.1)
    assert truths["drive torque less wheel spin-up"] == pytest.approx(19.0, rel=0.1)
    assert truths["drive torque less steered-wheel projection"] == pytest.approx(1.25, rel=0.15)


@pytest.mark.slow       # 12 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_commonroad_without_camber_force_meets_the_paper():
    """The v_y and delta gap on the multi-body plant is the tyres' camber force (the body's roll
    cambers the wheels; the package's PAC2002 multiplies its offsets p_hy1, p_vy1 by sgn(gamma)):
    the same run with the camber terms off meets the paper's scenario-2 MAE of v_y and T_eng."""
    cfg = observers.get("ts_fuzzy_uio_bmw320i")
    res = ts_validation.run(cfg, "circular_path_normal", "commonroad", camber_force=False)
    obs = res["paper_format"]["rows"]        # Table II: SI units, delta in rad
    seed = ts_validation.PAPER_TABLE_II["circular_path_normal"]
    assert res["status_flags"] == 0
    assert obs["v_y"]["MAE"] <= seed["v_y"][0]                   # 4.1e-4 (paper 5.66e-4)
    assert obs["T_eng"]["MAE"] <= seed["T_eng"][0]               # 0.033 (paper 0.733)
    assert obs["delta"]["MAE"] <= 1.15 * 1.03e-4                 # 1.03e-4 (paper 9.71e-5)
    assert obs["v_y"]["MAE"] < 0.05 * COMMONROAD_MEASURED["v_y"][0]


def test_commonroad_ablation_knobs_are_checked():
    from codegen.validation import commonroad_angle
    cfg = observers.get("ts_fuzzy_uio_bmw320i")
    scn = common.scenario_for(cfg, "circular_path_normal", 1.0)
    with pytest.raises(commonroad_angle.PlantError, match="roll_stiffness_scale"):
        commonroad_angle.simulate(scn, 2, 100.0, roll_stiffness_scale=0.0)
    with pytest.raises(ModelDefinitionError, match="commonroad plant only"):
        ts_validation.run(observers.get(NAME), "circular_path_normal", "nominal", camber_force=False)


@pytest.mark.slow          # the compiled observer
def test_real_data_with_delta_as_unknown_input():
    from codegen.validation import run as validate
    from codegen.validation import logs
    res = logs.run("ts_fuzzy_uio_stanford", "stanford")
    beta, delta = res["observer"]["beta"], res["observer"]["delta"]
    kf = res["baselines"]["linear_kf"]["beta"]
    assert beta["rms"] <= 1.02 * kf["rms"]          # the same linear tyre model as the KF
    assert delta["unit"] == "deg" and delta["rms"] < 1.5     # delta is reconstructed, not measured
    assert res["status_flags"] <= 1                  # the warm-up sample


def test_a_speed_box_from_zero_says_its_min_must_be_above_zero(tmp_path):
    """[state_bounds] v_x = [0, 30]: the TS form divides by v_x. It said 'division by an interval
    containing 0' and to loosen bounds_rel_tol / bounds_max_boxes, which cannot fix it; it names the
    signal's box in the parameter file and that its min must be above 0."""
    import re
    from codegen.errors import BoundsError
    config = observers.get(NAME)
    params = open(config.parameter_path).read()
    assert "\nv_x = [5.0, 30.0]" in params
    (tmp_path / "p.toml").write_text(params.replace("\nv_x = [5.0, 30.0]", "\nv_x = [0.0, 30.0]"))
    text = open(config.source).read()
    (tmp_path / "o.toml").write_text(re.sub(r'(?m)^parameters = .*$', 'parameters = "p.toml"', text))
    with pytest.raises(BoundsError) as err:
        pipeline.solve(observers.get(str(tmp_path / "o.toml")))
    msg = str(err.value)
    assert err.value.singular == ("v_x",)
    assert "1/v_x divides by v_x, whose range [0, 30] contains 0" in msg
    assert "[state_bounds] v_x = [0, 30] reaches 0: its min must be above 0" in msg
    assert "bounds_rel_tol" not in msg and "bounds_max_boxes" not in msg


def _wheel_model(drag):
    """Longitudinal speed v and wheel speed w, both measured: every nonlinearity is a measured
    consequent f_v, which the step evaluates and nothing bounds."""
    v, w, T_e, T_b = sp.symbols("v w T_e T_b")
    m, J, R, F, k, c, v0 = sp.symbols("m J R F k c v0", positive=True)
    F_x = F * sp.tanh(k * (R * w - v) / sp.Max(sp.Abs(v), v0))
    return ModelDefinition("wheel", (v, w), (T_b,), (T_e,),
                           sp.Matrix([(F_x - c * drag(v)) / m, (T_e - T_b - R * F_x) / J]),
                           (("v", v), ("w", w)), (), (m, J, R, F, k, c, v0))


def _wheel_params(v_box):
    from codegen.model.definition import ParameterSet
    return ParameterSet("car.toml", {"m": 1400.0, "J": 1.2, "R": 0.31, "F": 6000.0, "k": 12.0, "c": 0.4,
                                     "v0": 1.0}, {}, {}, state_bounds={"v": v_box, "w": (0.0, 140.0)},
                        inputs={"T_b": {"min": 0.0, "max": 800.0}})


def test_a_measured_consequent_undefined_inside_the_box_is_refused():
    """v sqrt(v) with v in [-2, 40] is complex for v < 0: the design was certified, generated, and
    `uiogen build` died with a TypeError traceback in the numpy reference (the C gives NaN there).
    It is refused before any design, naming the row and a point; the same law on a box where it
    is defined, and |v| v on the wider box, are accepted."""
    undefined = _wheel_model(lambda v: v * sp.sqrt(v))
    with pytest.raises(SchedulingBoundsError, match=r"dv/dt is a complex number at v = -2, .*car\.toml"):
        ts_fuzzy.build(undefined, _wheel_params((-2.0, 40.0)), 0.01)
    ts_fuzzy.build(undefined, _wheel_params((0.0, 40.0)), 0.01)
    ts_fuzzy.build(_wheel_model(lambda v: v * sp.Abs(v)), _wheel_params((-2.0, 40.0)), 0.01)
    division = _wheel_model(lambda v: 1 / v)
    with pytest.raises(SchedulingBoundsError, match=r"dv/dt is not finite at v = 0, "):
        ts_fuzzy.build(division, _wheel_params((0.0, 40.0)), 0.01)


SOLVED_TWICE = '''
import sympy as sp
from codegen.model import ModelDefinition, load_parameters

v_y, r, delta, T, F_w = sp.symbols("v_y r delta T F_w")
v_x = sp.Symbol("v_x", positive=True)
M, l_f, l_r, l_w, I_e, I_z, F_f, F_r = sp.symbols("M l_f l_r l_w I_e I_z F_f F_r", positive=True)
# the tyre laws as sp.solve writes them into the two rows: coefficients that differ in the last digit
k_f, k_f2 = sp.Float(12.5), sp.Float(12.500000000000002)
k_r, k_r2 = sp.Float(16.428571428571427), sp.Float(16.42857142857143)
front = lambda k: F_f * sp.tanh(k * (delta - (v_y + l_f * r) / v_x))
rear = lambda k: F_r * sp.tanh(k * (l_r * r - v_y) / v_x)
MODEL = ModelDefinition(
    name="solved_twice", states=(v_x, v_y, r), known_inputs=(delta, T), unknown_inputs=(F_w,),
    dynamics=sp.Matrix([T / I_e + v_y * r, (front(k_f) + rear(k_r) + F_w) / M - v_x * r,
                        (l_f * front(k_f2) - l_r * rear(k_r2) + l_w * F_w) / I_z]),
    outputs=(("v_x", v_x), ("r", r)), scheduling=(), parameters=(M, l_f, l_r, l_w, I_e, I_z, F_f, F_r),
    units={"v_x": "m/s", "v_y": "m/s", "r": "rad/s", "T": "N m", "F_w": "N", "delta": "rad"})
'''
SOLVED_TWICE_PARAMS = """[parameters]
M = 1600.0
l_f = 1.25
l_r = 1.45
l_w = 0.6
I_e = 480.0
I_z = 2300.0
F_f = 8000.0
F_r = 7000.0

[state_bounds]
v_x = [15.0, 30.0]
v_y = [-0.5, 0.5]
r = [-0.3, 0.3]

[inputs]
delta = { min = -0.03, max = 0.03, bandwidth = 0.5 }
T = { min = -150.0, max = 250.0, bandwidth = 0.3 }
F_w = { min = -500.0, max = 500.0, bandwidth = 0.2 }
"""


def test_a_tyre_law_written_twice_with_float_noise_is_one_consequent(tmp_path):
    """Issue 42, item 6: after sp.solve one tyre law sits in two rows with coefficients that differ
    in the last digit; it is one unmeasured consequent per axle (4 DMVT vertices, not 16), and the
    design certifies (with 16 vertices Clarabel answered PrimalInfeasible)."""
    (tmp_path / "car.py").write_text(SOLVED_TWICE)
    (tmp_path / "car.toml").write_text(SOLVED_TWICE_PARAMS)
    path = tmp_path / "own.toml"
    path.write_text(f'family = "{NAME}"\nmodel = "car.py"\nparameters = "car.toml"\nsample_time = 0.01\n')
    config = observers.get(str(path))
    ts = ts_fuzzy.build(config.design_model(), load_parameters(config.parameter_path), 0.01)
    assert len(ts.phi) == 2 and ts.theta_vertices.shape[0] == 4
    b = pipeline.build(config)
    assert b.figures()["dmvt_vertices"] == 4
