"""Sentouh et al. 2023: interconnected longitudinal-lateral LPV UIO (``interconnected_uio``, issue 7).

Correctness only: the derivation from the one vehicle model, the design conditions and their
re-check, the generated step against its numpy reference and CasADi, and the validation runs
(regression bounds around the README's figures)."""
import dataclasses
import tomllib
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from codegen.families.interconnected_uio import representation as icm
from codegen.project import observer_file as observers
from codegen.families.interconnected_uio import design as du
from codegen.families.interconnected_uio import build as dub
from codegen.errors import (CertificateError, ModelDefinitionError, RankConditionError, SchedulingBoundsError)
from codegen.model import load_parameters
from codegen.design.solver import FreshSolver
from python_bindings import load

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
NAME = "interconnected_uio"
TWIN = "interconnected_uio_ford_escort"


@pytest.fixture(scope="module")
def icb(built):
    return built(NAME)


@pytest.fixture(scope="module")
def compiled():
    return load(NAME)


def _model():
    from model_defs.interconnected_vehicle import MODEL
    return MODEL


def _params():
    return load_parameters(ROOT / "model_defs" / "params" / "sentouh2023_twingo.toml")


def test_toolchain_splits_the_model_and_finds_the_coupling(icb):
    ts = icb.ts
    lon, lat = ts.subsystems
    assert [str(s) for s in lon.states] == ["v_x", "omega_f", "omega_r", "F_xf", "F_xr"]
    assert [str(s) for s in lat.states] == ["v_y", "r", "psi_L", "y_L", "F_yf", "F_yr", "delta", "delta_dot"]
    assert [str(u) for u in lon.unknown_inputs] == ["T_Bf", "B_r"]
    assert [str(u) for u in lat.unknown_inputs] == ["T_s", "kappa"]
    assert lon.output_names == ("omega_f", "omega_r", "a_x")
    assert lat.output_names == ("r", "psi_L", "y_L", "a_y", "delta", "delta_dot")
    # zeta_F of (8): v_y r and F_rr into the longitudinal, F_w into the lateral subsystem; the Twingo's
    # aerodynamic drag c_a v_x^2 enters the accelerometer output as one more coupling signal
    assert {c.name for c in lon.coupling} == {"r*v_y", "F_rr", "v_x**2"}
    assert [c.name for c in lat.coupling] == ["F_w"]
    # premises (11): v_x and the switched slip signals q_i (7) times v_x; lateral v_x and 1/v_x
    assert [str(p.expr) for p in lon.premises] == ["v_x", "q_f*v_x", "q_r*v_x"]
    assert [sp.simplify(p.expr) for p in lat.premises] == [sp.Symbol("v_x"), 1 / sp.Symbol("v_x")]
    assert (lon.n_vertices, lat.n_vertices) == (8, 4)
    assert [(p.lower, p.upper) for p in lon.premises[1:]] == [(0.8, 1.0), (0.8, 1.0)]
    # kappa enters as -kappa v_x: the unknown input becomes kappa' = v_x kappa, B is constant
    assert [str(g) for g in lat.ui_scales] == ["1", "v_x"]
    assert lat.B[2, 1] == -1.0 and lat.B[3, 1] == -5.0


@pytest.mark.slow       # 7 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_ts_form_is_exact(icb):
    assert icm.vertex_check(icb.ts, samples=300) < 1e-12


def test_switched_signal_is_max_of_eq7(icb):
    q_f = icb.ts.switched[sp.Symbol("q_f", positive=True)]
    f = sp.lambdify(sorted(q_f.free_symbols, key=str), q_f)
    R = icb.ts.parameters.values["R"]
    assert f(80.0, 20.0) == pytest.approx(1.0 / (R * 80.0))   # traction: R w = 23.3 m/s > v_x
    assert f(40.0, 30.0) == pytest.approx(1.0 / 30.0)         # braking: v_x > R w = 11.7 m/s


def test_model_errors_are_clear(tmp_path):
    m = _model()
    with pytest.raises(ModelDefinitionError, match="two subsystems"):
        dataclasses.replace(m, subsystems=(m.subsystems[0], ("lateral", (*m.subsystems[1][1], sp.Symbol("v_x")))))
    with pytest.raises(ModelDefinitionError, match="undeclared"):
        dataclasses.replace(m, dynamics=tuple((s, e + sp.Symbol("zzz") if str(s) == "r" else e) for s, e in m.dynamics))
    # a premise of a switched signal needs its range in [premise_bounds]
    text = (ROOT / "model_defs" / "params" / "sentouh2023_twingo.toml").read_text()
    path = tmp_path / "twingo_without_premise_bounds.toml"
    path.write_text(text.split("[premise_bounds]")[0])
    with pytest.raises(SchedulingBoundsError, match="premise_bounds"):
        icm.build(m, load_parameters(path))
    # an unknown input entering both subsystems has no owner (its coefficient 3 may carry the unit
    # that makes the term an angular acceleration, so the units check lets the structure check speak)
    kappa, T_Bf = sp.Symbol("kappa"), sp.Symbol("T_Bf")
    both = dataclasses.replace(m, dynamics=tuple((s, e + 3 * kappa if str(s) == "omega_f" else e)
                                                 for s, e in m.dynamics))
    with pytest.raises(ModelDefinitionError, match="each must enter exactly one"):
        icm.build(both, _params())
    del T_Bf


def test_matching_condition_fails_without_the_delta_dot_output():
    """(16) with the printed lateral outputs: T_s has relative degree 2, rank(CB) = 1 < rank(B) = 2."""
    m = _model()
    printed = dataclasses.replace(m, outputs=tuple((n, e) for n, e in m.outputs if n != "delta_dot"))
    ts = icm.build(printed, _params())
    with pytest.raises(RankConditionError, match=r"\(16\).*rank\(CB\) = 1 != rank\(B\) = 2"):
        du.decoupling(ts.subsystems[1])
    du.decoupling(ts.subsystems[0])        # the longitudinal subsystem is fine


def test_decoupling_and_gains(icb):
    for sub, sd in zip(icb.ts.subsystems, icb.design.subsystems):
        np.testing.assert_allclose(sd.T @ sub.B, 0.0, atol=1e-12)
        np.testing.assert_allclose(np.eye(sub.n) + sd.H @ sub.C, sd.T, atol=1e-15)
        # measured-rows member: T has zero rows for the states an output reads directly
        for k in range(sub.ny):
            nz = np.flatnonzero(sub.C[k])
            if len(nz) == 1 and sub.C[k, nz[0]] == 1.0:
                np.testing.assert_allclose(sd.T[nz[0]], 0.0, atol=1e-15)
        for i in range(sub.n_vertices):
            # (28) and (25): N = Gamma - K C, L = K - N H
            np.testing.assert_allclose(sd.N[i], sd.T @ sub.A[i] - sd.K[i] @ sub.C, rtol=1e-12, atol=1e-9)
            np.testing.assert_allclose(sd.L[i], sd.K[i] - sd.N[i] @ sd.H, rtol=1e-12, atol=1e-9)
            # Phi of (20) vanishes: T A - L C - N T = 0 (T' = 0)
            Phi = sd.T @ sub.A[i] - sd.L[i] @ sub.C - sd.N[i] @ sd.T
            assert np.abs(Phi).max() <= 1e-9 * max(1.0, np.abs(sub.A[i]).max())
            assert np.linalg.eigvals(sd.N[i]).real.max() < 0
        # affine gain structure: the vertex gains are an affine function of the premises
        assert du.affine_parts(sub, sd.Omega) is not None


@pytest.mark.parametrize("mode", ["measured_rows", "minimum_norm"])
def test_force_split_is_the_unobservable_mode(icb, mode):
    """Assumption 1(ii): (T A_i, C) detectable at every vertex. The only unobservable mode is the
    relaxation -v_x/sigma of the axle-force split: F_xf - F_xr always (the torques are unknown), and
    F_yf - F_yr with the measured-rows H, whose zero r row of T gives up the yaw equation."""
    sigma = icb.ts.parameters.values["sigma"]
    design = icb.design if mode == "measured_rows" else \
        du.design(icb.ts, dataclasses.replace(icb.design.settings, decoupling=mode), FreshSolver())
    for sub, sd in zip(icb.ts.subsystems, design.subsystems):
        S = np.diag(sd.S)
        for i, theta in enumerate(du.vertex_premises(sub)):
            A = np.linalg.solve(S, sd.T @ sub.A[i] @ S)
            C = sub.C @ S / sd.W[:, None]
            bad = [lam for lam in np.linalg.eigvals(A)
                   if np.linalg.svd(np.vstack([lam * np.eye(sub.n) - A, C]), compute_uv=False)[-1] < 1e-9]
            if sub.name == "longitudinal" or mode == "measured_rows":
                assert len(bad) == 1 and bad[0] == pytest.approx(-theta[0] / sigma, rel=1e-9)
            else:
                assert not bad


def test_minimum_norm_decoupling_is_26(icb):
    sub = icb.ts.subsystems[1]
    H, T, CBp = du.decoupling(sub, mode="minimum_norm")
    np.testing.assert_allclose(H, -sub.B @ np.linalg.pinv(sub.C @ sub.B), atol=1e-14)
    with pytest.raises(ModelDefinitionError, match="decoupling must be"):
        du.ICDesignSettings(decoupling="other")


def test_certificates(icb):
    cert, disc = icb.recheck, icb.discrete
    assert cert["worst_min_eig"] > 0
    for name in ("longitudinal", "lateral"):
        assert cert[name]["max_scaled_gain_norm"] <= icb.design.settings.gain_bound * (1 + 1e-6)
        assert disc[name]["max_V_ratio"] < 1.0 / (1 + icb.design.settings.alpha * 0.01) + 1e-12
        assert disc[name]["min_eig_M_sym"] > 0
    # a tampered design is refused by the independent re-check
    sd = icb.design.subsystems[0]
    bad = dataclasses.replace(sd, P=sd.P - 0.5 * np.eye(sd.P.shape[0]))
    with pytest.raises(CertificateError, match=r"\(27"):
        du.certify(icb.ts, dataclasses.replace(icb.design, subsystems=(bad, icb.design.subsystems[1])))


def test_design_time_and_vertex_gain_option(icb):
    assert icb.timings["representation_s"] + icb.timings["design_s"] < 30.0
    # the printed free Omega_i are also solvable and certified (the step then blends 2^q vertices)
    ts = icb.ts
    d = du.design(ts, dataclasses.replace(icb.design.settings, gain_structure="vertex"), FreshSolver())
    assert du.certify(ts, d)["worst_min_eig"] > 0


@pytest.mark.slow       # 6 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_differentiator_configuration_errors(icb):
    cfg = observers.get(NAME)
    table = dict(cfg.design)
    table["differentiators"] = {k: v for k, v in table["differentiators"].items() if k != "psi_L"}
    with pytest.raises(ModelDefinitionError, match="d/dt psi_L"):
        dub.build(dataclasses.replace(cfg, design=table), FreshSolver())
    table = dict(cfg.design)
    table["differentiators"] = {**table["differentiators"], "delta": {"order": 1, "lipschitz": 10.0}}
    with pytest.raises(ModelDefinitionError, match="order >= 2"):
        dub.build(dataclasses.replace(cfg, design=table), FreshSolver())
    with pytest.raises(ModelDefinitionError, match="unknown \\[design\\] keys"):
        dub.build(dataclasses.replace(cfg, design={**cfg.design, "alhpa": 1.0}), FreshSolver())


SCALE = {"v_x": 20.0, "omega_f": 60.0, "omega_r": 60.0, "F_xf": 500.0, "F_xr": 300.0, "v_y": 0.1, "r": 0.1,
         "psi_L": 0.01, "y_L": 0.1, "F_yf": 800.0, "F_yr": 600.0, "delta": 0.02, "delta_dot": 0.05}


def _random_state(rng, icb):
    """A primed state near a driving point: UIO states, differentiator states, previous outputs."""
    names = icb.state_names
    z = 0.3 * rng.normal(size=len(names))
    for i, n in enumerate(names):
        base = n.split("_", 1)[1] if n[:2] in ("z_", "d0", "d1", "d2", "d3") else n
        z[i] *= SCALE.get(base, 1.0)
    vx = rng.uniform(8.0, 30.0)
    for n in ("z_v_x", "v_x"):
        z[names.index(n)] = vx
    for n in ("z_omega_f", "z_omega_r", "d0_omega_f", "d0_omega_r"):
        z[names.index(n)] += vx / 0.2915
    z[names.index("primed")] = 1.0
    return z


@pytest.mark.slow          # the compiled observer
def test_c_step_matches_numpy_and_casadi(icb, compiled):
    rng = np.random.default_rng(3)
    f = icb.step_function()
    out = np.empty(compiled.n_output)
    worst = 0.0
    for _ in range(600):
        z = _random_state(rng, icb)
        vx = z[icb.state_names.index("v_x")]
        y = np.array([vx / 0.2915 * (1 + 0.02 * rng.normal()), vx / 0.2915 * (1 + 0.02 * rng.normal()),
                      rng.normal(), 0.2 * rng.normal(), 0.02 * rng.normal(), 0.3 * rng.normal(), 2 * rng.normal(),
                      0.03 * rng.normal()])
        ref, excess, warm = icb.step_numpy(z, [], y)
        cas = np.asarray(f(z, np.zeros(0), y, np.zeros(0))[0]).ravel()
        s = z.copy()
        status = compiled.step(s, y, out)
        assert status == (compiled.status_bits["SCHEDULING_CLAMPED"] if excess > 0 else 0)
        np.testing.assert_array_equal(s, cas)          # C is CasADi's own code: bit-identical
        worst = max(worst, np.abs(s - ref).max() / np.abs(ref).max())
        np.testing.assert_array_equal(out, s[-compiled.n_output:])
    assert worst <= 1e-12


@pytest.mark.slow          # the compiled observer
def test_c_step_status_behaviour(compiled):
    bits = compiled.status_bits
    s, out = compiled.initial_state(), np.empty(compiled.n_output)
    y = np.array([60.0, 60.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert compiled.step(s, y, out) == bits["WARMING_UP"]
    # the first sample starts v_x from the wheel speeds (output: after one update from that start)
    assert out[compiled.output_index("v_x")] == pytest.approx(0.2915 * 60.0, rel=1e-3)
    assert compiled.step(s, y, out) == 0
    held = s.copy()
    assert compiled.step(s, np.array([np.nan, *y[1:]]), out) == bits["NONFINITE_INPUT"]
    np.testing.assert_array_equal(s, held)
    assert compiled.step(s, np.array([60.0, 60.0, 0, 0, 0, 0, 0, 0.7]), out) & bits["SCHEDULING_CLAMPED"]
    assert np.isfinite(s).all()


@pytest.mark.slow          # the compiled observer
def test_straight_driving_is_reproduced_exactly(compiled):
    """Steady straight driving at 20 m/s, consistent measurements: every estimate converges to the
    truth, the unknown inputs to the steady torques (rolling resistance and drag on the front axle)."""
    p = load_parameters(ROOT / "model_defs" / "params" / "sentouh2023_twingo.toml").values
    v = 20.0
    resist = 155.3 + p["c_a"] * v * v
    # steady state of the model: F_xf = resist (front drive), slip lambda_f = F_xf / C_lf
    lam = resist / p["C_lf"]
    wf = v / (1 - lam) / p["R"]      # traction: lambda = (R w - v)/(R w) -> R w = v/(1 - lambda)
    wr = v / p["R"]
    row = np.array([wf, wr, (resist - 155.3 - p["c_a"] * v * v) / p["m"], 0.0, 0.0, 0.0, 0.0, 0.0])
    out, status, _ = compiled.run(np.tile(row, (1500, 1)))
    est = dict(zip(compiled.output_names, out[-1]))
    assert est["v_x"] == pytest.approx(v, rel=1e-6)
    assert est["F_xf"] == pytest.approx(resist, rel=1e-5)
    assert est["T_Bf"] == pytest.approx(p["R"] * resist, rel=1e-4)
    assert abs(est["B_r"]) < 1e-3 and abs(est["kappa"]) < 1e-9 and abs(est["T_s"]) < 1e-6
    assert not np.any(status[1:])


@pytest.mark.slow       # 4 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_model_plant_run_is_nearly_exact():
    """On the observer's own model (1)-(7) the errors are those of discretization and differentiators."""
    from codegen.families.interconnected_uio import validation as satory
    r = satory.run(TWIN, 1.0, "model", duration=30.0)
    t = r["table"]
    assert r["flagged_after_settle"] == 0
    for s in ("r", "omega_f", "omega_r", "delta", "v_x", "v_y", "a_y"):
        assert t[s]["rmse_percent_of_max"] < 0.1, s
    for s in ("kappa", "T_s", "a_x"):
        assert t[s]["rmse_percent_of_max"] < 1.0, s
    for s in ("T_Bf", "B_r"):
        assert t[s]["rmse_percent_of_max"] < 6.0, s


# Our Table 1 on the CommonRoad plant (whole Satory-like track, every sample after 2 s), (RMSE%, NMSE%)
# per signal: `uiogen validate interconnected_uio_ford_escort --scenario satory_table1`, docs page.
OURS_TABLE1 = {
    1.0: {"r": (0.04234, 100), "omega_f": (0.02899, 100), "omega_r": (0.02694, 100), "T_Bf": (3.156, 98.84), "a_x": (0.8631, 99.9), "a_y": (1.962, 99.8), "delta": (0.08868, 100), "B_r": (6.794, 90.18), "kappa": (0.2062, 100), "v_x": (0.1054, 99.99), "v_y": (4.009, 96.92), "T_s": (4.396, 99.08)},
    0.6: {"r": (0.04713, 100), "omega_f": (0.0172, 100), "omega_r": (0.0144, 100), "T_Bf": (4.18, 99.27), "a_x": (0.9288, 99.95), "a_y": (3.22, 99.63), "delta": (0.08108, 100), "B_r": (8.182, 93.58), "kappa": (0.1265, 100), "v_x": (0.07246, 100), "v_y": (3.807, 98.4), "T_s": (3.229, 99.51)},
    0.4: {"r": (0.03658, 100), "omega_f": (0.0113, 100), "omega_r": (0.008676, 100), "T_Bf": (5.155, 99.21), "a_x": (0.9907, 99.96), "a_y": (3.086, 99.68), "delta": (0.05247, 100), "B_r": (12.25, 89.26), "kappa": (0.1244, 100), "v_x": (0.02873, 100), "v_y": (2.39, 99.52), "T_s": (2.429, 99.67)},
}


@pytest.mark.slow       # 61 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
@pytest.mark.parametrize("mu", (1.0, 0.6, 0.4))
def test_commonroad_table1_at_each_friction(mu):
    """The full Table 1 run at mu = 1, 0.6, 0.4: every RMSE% within 5 % of ours above (0.005 points
    at least), every NMSE% within 0.3 points; the paper's comparisons as the docs state them: at
    mu = 1 every RMSE% within 1.5 x the paper's; on NMSE% (the unambiguous metric of (32)) the
    braking torques T_Bf and B_r are the signals below the paper (a_y too at mu = 0.6, by 0.13); B_r at
    mu = 0.4 is the accepted miss (RMSE% > 9.2)."""
    from codegen.families.interconnected_uio import validation as satory
    r = satory.run(TWIN, mu, "commonroad")
    assert r["flagged_after_settle"] == 0
    paper = satory.PAPER_TABLE1[mu]
    for s in satory.TABLE1_SIGNALS:
        rm, nm = OURS_TABLE1[mu][s]
        row = r["table"][s]
        assert row["rmse_percent_of_max"] == pytest.approx(rm, rel=0.05, abs=0.005), s
        assert row["nmse_percent"] == pytest.approx(nm, abs=0.3), s
    below = {s for s in satory.TABLE1_SIGNALS if r["table"][s]["nmse_percent"] < paper[s][1]}
    assert below == ({"T_Bf", "B_r", "a_y"} if mu == 0.6 else {"T_Bf", "B_r"})
    if mu == 1.0:
        assert all(r["table"][s]["rmse_percent_of_max"] <= 1.5 * paper[s][0] for s in satory.TABLE1_SIGNALS)
        assert r["min_ax"] < -5.0 and r["max_abs_ay"] > 4.0
    if mu == 0.4:
        over = {s for s in satory.TABLE1_SIGNALS if r["table"][s]["rmse_percent_of_max"] > 9.2}
        assert over == {"B_r"}


def test_paper_rmse_nmse_pairs_are_not_one_reading():
    """Under the normalized RMSE% reading, the paper's (RMSE%, NMSE%) pairs imply std/max of the
    truth 0.98 for T_Bf (a mostly-zero braking torque: ours 0.29) and 0.034 for kappa (ours 0.33)."""
    from codegen.families.interconnected_uio import validation as satory
    imp = {s: satory.implied_std_over_max(*satory.PAPER_TABLE1[1.0][s]) for s in satory.TABLE1_SIGNALS}
    assert imp["T_Bf"] == pytest.approx(0.984, abs=1e-3) and imp["kappa"] == pytest.approx(0.0339, abs=1e-3)
    t = np.arange(0.0, 20.0, 0.01)
    y = np.sin(t)
    m = satory.table1_metrics(y, y + 0.05 * np.cos(3 * t), t)
    assert satory.implied_std_over_max(m["rmse_percent_of_max"], m["nmse_percent"]) == pytest.approx(
        m["std_over_max_truth"], rel=1e-9)


def test_table1_metrics():
    from codegen.families.interconnected_uio import validation as satory
    t = np.arange(0, 10, 0.01)
    y = np.sin(t)
    m = satory.table1_metrics(y, y + 0.01, t)
    assert m["rmse_percent_of_max"] == pytest.approx(100 * 0.01 / np.abs(y[t >= 2]).max())
    assert m["rmse_percent_literal"] == pytest.approx(1.0)
    assert m["nmse_percent"] == pytest.approx(100 - 100 * 0.01 ** 2 / np.var(y[t >= 2]), rel=1e-9)


def test_commonroad_parameter_file_is_derived_from_the_package():
    """Regenerates the committed twin parameter file from the package and the committed identification
    (the identification itself: next test)."""
    from codegen.families.interconnected_uio import validation as satory
    committed = (ROOT / "model_defs" / "params" / "commonroad_ford_escort_interconnected.toml").read_text()
    fits = {}
    for line in committed.splitlines():
        if "identified, R^2" in line:
            name, rest = line.split("=", 1)
            fits[name.strip()] = (float(rest.split("#")[0]), float(rest.split("R^2 ")[1].split(" ")[0]))
    assert set(fits) == {"C_f", "C_r", "C_lf", "C_lr", "t_sb"}
    assert satory.params_toml(1, fits) == committed


@pytest.mark.slow       # 14 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_identification_reproduces_the_committed_coefficients():
    from codegen.families.interconnected_uio import validation as satory
    committed = tomllib.loads((ROOT / "model_defs" / "params" / "commonroad_ford_escort_interconnected.toml").read_text())
    fits = satory.identify(1)
    for k, (value, r2) in fits.items():
        assert value == pytest.approx(committed["parameters"][k], rel=1e-9), k
        assert r2 > 0.9
    # load transfer: under braking the rear axle's effective slip stiffness is about half its static slope
    assert fits["C_lr"][0] < 0.6 * 102807.0


def test_identification_calibration_drive_arguments_are_checked():
    """frictions / braking of the calibration drive: typed error before any simulation."""
    from codegen.families.interconnected_uio import validation as satory
    for bad in ({"frictions": ()}, {"frictions": (1.0, 0.0)}, {"braking": ()}, {"braking": (0.6, 1.5)}):
        with pytest.raises(ModelDefinitionError, match="calibration"):
            satory.identify(1, **bad)
    # the effective rolling radius comes from a free-rolling rear axle: not on a rear-wheel-drive car
    with pytest.raises(ModelDefinitionError, match="calibration"):
        satory.identify(2, effective_radius=True)


def _rolling_resistance_project(tmp_path, fixed: bool):
    """The built-in model as a user's file with rolling resistance -f_r g written into dv_x/dt (f_r, g
    parameters), or with the refusal's fix applied to it (``fixed``: the term an exogenous signal k_v_x
    at its nominal value -f_r g)."""
    src = (ROOT / "model_defs" / "interconnected_vehicle.py").read_text()
    model = (src.replace('c_a = sp.Symbol("c_a", nonnegative=True)',
                         'c_a = sp.Symbol("c_a", nonnegative=True)\nf_r, g = sp.symbols("f_r g", positive=True)')
             .replace("R_s, B_s, t_sb, c_a),", "R_s, B_s, t_sb, c_a, f_r, g),"))
    params = (ROOT / "model_defs" / "params" / "sentouh2023_twingo.toml").read_text()
    params = params.replace("[parameters]\n", "[parameters]\nf_r = 0.012\ng = 9.81\n", 1)
    if fixed:
        model = (model.replace('F_rr, F_w = sp.symbols("F_rr F_w")', 'F_rr, F_w, k_v_x = sp.symbols("F_rr F_w k_v_x")')
                 .replace("exogenous=(F_rr, F_w),", "exogenous=(F_rr, F_w, k_v_x),")
                 .replace("- F_a - F_rr) / m,", "- F_a - F_rr) / m + k_v_x,", 1))
        params = params.replace("[exogenous]\n", f"[exogenous]\nk_v_x = {-0.012 * 9.81!r}\n", 1)
    else:
        model = model.replace("- F_a - F_rr) / m,", "- F_a - F_rr) / m - f_r * g,", 1)
    assert model.count("k_v_x" if fixed else "f_r * g,") >= 1
    (tmp_path / "car.py").write_text(model)
    (tmp_path / "car.toml").write_text(params)
    obs = (ROOT / "model_defs" / "observers" / f"{NAME}.toml").read_text()
    lines = ['model = "car.py"' if ln.startswith("model =") else 'parameters = "car.toml"' if ln.startswith("parameters =")
             else ln for ln in obs.splitlines()]
    (tmp_path / "obs.toml").write_text("\n".join(lines) + "\n")
    return tmp_path / "obs.toml"


def test_a_constant_term_is_refused_naming_the_file_the_term_and_the_fix(tmp_path):
    """Rolling resistance -f_r g (a term of parameters alone) was refused as 'neither a premise times one own
    state ...' naming neither the file nor the term as written: the refusal names both, its value, what the
    family takes and the exogenous signal that carries it."""
    from codegen.errors import NotAffineError
    config = observers.get(str(_rolling_resistance_project(tmp_path, fixed=False)))
    with pytest.raises(NotAffineError) as exc:
        icm.load(config)
    msg = str(exc.value)
    assert msg.startswith(f"{tmp_path / 'car.py'}: the term -f_r*g of dv_x/dt (subsystem longitudinal) is a constant "
                          f"(-0.11772 with the values of {tmp_path / 'car.toml'}); the interconnected UIO takes a term "
                          f"as a premise times one own state or unknown input, or a premise times a coupling signal"), msg
    assert msg.endswith(f"write k_v_x for -f_r*g in dv_x/dt, add k_v_x to exogenous=(...) of model "
                        f"'interconnected_vehicle' and k_v_x = -0.11772 to [exogenous] of {tmp_path / 'car.toml'}"), msg


@pytest.mark.slow       # one design of the interconnected UIO (about 10 s)
def test_the_constant_term_as_the_exogenous_signal_it_names_designs(tmp_path, capsys):
    """The refusal's fix applied: the constant an exogenous coupling signal at its nominal value designs
    (its column of D carries it; the lock is the built-in design's structure with one coupling signal more)."""
    from codegen import cli
    obs = _rolling_resistance_project(tmp_path, fixed=True)
    assert cli.main(["design", str(obs)]) == 0
    lon = icm.load(observers.get(str(obs))).subsystems[0]
    assert {c.name for c in lon.coupling} == {"r*v_y", "F_rr", "v_x**2", "k_v_x"}
