"""stanford_sideslip_nonlinear_tyre: the Fiala-tyre observer, its certificate and its figures on the shared log.

Figures measured on the shared half (27,500 samples) with the committed design; tolerances are
tight enough that a regression of the model, the identified parameters or the step breaks them.
"""
import numpy as np
import pytest
import sympy as sp

from codegen import families
from codegen.project import observer_file as observers
from codegen.errors import CertificateError
from codegen.validation import stanford

NAME = "stanford_sideslip_nonlinear_tyre"


@pytest.fixture(scope="module")
def built():
    return families.get("nonlinear_tyre_observer").build(observers.get(NAME))


def test_tyre_law_written_once_slope_and_sliding():
    from model_defs import tyres
    t, C, F = sp.symbols("t C F", positive=True)
    law = tyres.fiala_slip_force(t, C, F, clamp=False)
    t_sl = tyres.fiala_sliding_slip(C, F)
    assert sp.simplify(sp.diff(law, t) - C * (1 - t / t_sl) ** 2) == 0      # slope C (1 - t/t_sl)^2
    assert sp.simplify(law.subs(t, t_sl) - F) == 0                           # mu F_z at full sliding
    from model_defs import baselines
    a = sp.Symbol("a")
    assert baselines.fiala_axle_force(a, C, F) == tyres.fiala_slip_force(sp.tan(a), C, F)


def test_certificate_and_sound_slope_bounds(built):
    rep = built.rep
    # sound: every bound encloses what the force slope attains on the certified set
    for (lo, hi), (amin, amax) in zip(rep.theta, rep.theta_attained):
        assert lo <= amin and amax <= hi < 0
    # front: (1 - 0.9)^2 = 1 % of C_f survives at 0.9 t_sl; the product of the two factor bounds is
    # looser than the slope at the worst corner (-1084 N) but sound: -1019.0 N (measured; the slope
    # factor's lower bound is 1135 N against the 1207 N it attains, within the bounds' 1e-3 of C_f)
    worst_corner = -0.01 * 120700.0 * np.cos(0.2) * (np.cos(0.2) - 0.1149 * np.sin(0.2)) ** 2
    assert worst_corner <= rep.theta[0][1] == pytest.approx(-1019.05, rel=1e-3)
    assert rep.theta[1][1] == pytest.approx(-892.3, rel=1e-3) and rep.theta[0][0] == pytest.approx(-121972, rel=1e-3)
    c = built.certificate
    assert c["blocks"] == 9 and c["worst_min_eig"] > 0
    assert c["contraction_per_step"] <= 0.9999 + 1e-12
    # an independent numpy re-check of the emitted P at every vertex
    for _, A in built.verts:
        assert np.linalg.eigvalsh(A.T @ built.P @ A - 0.9999 ** 2 * built.P).max() < 0


def test_full_sliding_cannot_be_certified():
    cfg = observers.get(NAME)
    import dataclasses
    bad = dataclasses.replace(cfg, design={**cfg.design, "sliding_fraction": 0.999999, "decay": 0.9999})
    with pytest.raises(CertificateError):
        families.get("nonlinear_tyre_observer").build(bad)


def test_c_step_matches_reference(built):
    from codegen.extension.build import load
    obs = load(NAME)
    run = stanford.load()
    inputs = np.column_stack([run.delta, run.ay, run.yaw_rate, run.vx])[:2000]
    out, status, _ = obs.run(inputs)
    z = np.zeros(4)
    ref = []
    for row in inputs:
        z, _ = built.reference_step(z, row[:1], row[1:3], row[3:])
        ref.append(z[2:])
    assert np.allclose(out, np.array(ref), rtol=1e-10, atol=1e-12)


def test_real_log_figures():
    from codegen.validation import run as validate
    res = validate.run_data(NAME, "stanford")
    obs, base = res["observer"]["beta"]["rms"], res["baselines"]
    assert obs == pytest.approx(0.2908, abs=0.002)                      # <= 0.33 deg target
    assert obs <= base["ekf_nonlinear_tyre"]["beta"]["rms"] and obs <= base["ukf_nonlinear_tyre"]["beta"]["rms"]
    assert base["ekf_nonlinear_tyre"]["beta"]["rms"] == pytest.approx(0.3024, abs=0.002)
    assert base["ukf_nonlinear_tyre"]["beta"]["rms"] == pytest.approx(0.3025, abs=0.002)
    assert base["linear_kf"]["beta"]["rms"] == pytest.approx(0.678, abs=0.002)
    sp_ = res["splits"]
    assert sp_["identification"]["samples"] == 13750 and sp_["evaluation"]["samples"] == 13750
    assert sp_["evaluation"]["observer"] == pytest.approx(0.3014, abs=0.002)
    assert sp_["evaluation"]["observer"] <= 1.1 * obs                 # held-out part within 10 % of the whole
    assert res["status_flags"] == pytest.approx(1593, abs=20)           # 5.8 % outside the certified set
    peaks = {p["t"]: p["observer"] for p in res["peaks"]}
    assert peaks[110.0] == pytest.approx(1.01, abs=0.05)
    assert peaks[170.0] == pytest.approx(0.71, abs=0.05)
    assert peaks[207.0] == pytest.approx(1.58, abs=0.05)


def test_bench_reports_the_observer_within_the_issue_target():
    # uiogen bench iterates observers.names(): the design benchmark reads this family's settings
    # from the build itself (it has no separate design record), and the batch loop of the C step
    # stays within the issue's 500 ns/sample (measured about 27 ns)
    from codegen.tools import bench
    assert NAME in observers.names()
    r = bench.bench_observer(NAME)
    assert r["family"] == "nonlinear_tyre_observer"
    assert 0 < r["batch_ns_per_sample"] <= 500.0
    peer = r["design"]["cvxpy_clarabel"]
    if "objective" in peer:        # CVXPY is an optional dependency ('.[bench]')
        assert r["design"]["ours_clarabel"]["objective"] == pytest.approx(peer["objective"], rel=1e-6)


def test_demo_real_data_table_shows_the_observer_and_its_same_tyre_peers():
    from codegen.validation import demo
    from codegen.tools import docs
    real, others = demo.run_real_data()
    j = demo.real_data_json(real, others)
    assert {"stanford_sideslip_nonlinear_tyre", "ts_fuzzy_uio_stanford"} <= set(j["other_observers"])
    assert set(j["baselines"]) == {"linear_kf", "ekf"}                   # today's observer's baselines
    peers = {f"{p} ({NAME})" for p in ("ekf_nonlinear_tyre", "ukf_nonlinear_tyre")}
    assert set(j["other_baselines"]) == peers
    assert j["other_observers"][NAME]["beta"]["rms"] == pytest.approx(0.2908, abs=5e-4)
    assert j["other_baselines"][f"ekf_nonlinear_tyre ({NAME})"]["beta"]["rms"] == pytest.approx(0.3024, abs=5e-4)
    table = docs.real_data_table({"real_data": j})
    for row in (f"`{NAME}`", *peers, "linear_kf", "ekf", "`stanford_sideslip`"):
        assert row in table
    text = "\n".join(demo.real_data_lines(real, others))
    assert "ukf_nonlinear_tyre (peer of stanford_sideslip_nonlinear_tyre" in text
