"""It runs and converges: compiled C step vs the exact nonlinear-in-speed plant, in closed loop."""
import numpy as np
import pytest

from codegen.project import observer_file as observers
from codegen.validation import simulate, run as validate
from codegen.validation import common

pytestmark = pytest.mark.slow          # the compiled extension on simulated runs


def test_converges_on_track_scenario_with_noise():
    r = validate.run_scenario("lpv_linf_driver_torque", "track_varying_speed", "model")
    t = r["observer"]
    assert r["status_flags"] == 0
    # measured beta 0.1047 deg / T_d 0.981 N m / r 0.0314 deg/s RMS (a_y up to 5.5 m/s^2), 5 % either way.
    # Nguyen et al. 2019 Table II (0.053 deg / 0.25 N m) is not reached with the paper's Taylor-reduced
    # polytope: its 14.8 % error on a_12 is the cause (the same gains with the exact A(v_x) in the step:
    # 0.0087 deg / 0.27 N m; docs/families/linf_uio.md), see test_sector_polytope_reaches_table_ii
    assert t["beta"]["rms"] == pytest.approx(0.1047, rel=0.05)
    assert t["T_d"]["rms"] == pytest.approx(0.981, rel=0.05) and t["T_d"]["max"] < 3.2
    assert t["r"]["unit"] == "rad/s" and np.degrees(t["r"]["rms"]) == pytest.approx(0.0314, rel=0.05)
    assert r["paper_format"]["rows"]["r"]["RMS"] == pytest.approx(0.0314, rel=0.05)      # Table II: deg/s


def test_sector_polytope_reaches_table_ii():
    """The exact 4-vertex polytope, same Theorem 1 and settings: on the observer's exact model the
    errors reach the paper's Table II (beta RMS 0.053 deg, T_d RMS 0.25 N m on its simulator);
    measured 0.0036 deg and 0.269 N m (a linear KF on the same run: 0.0029 deg)."""
    r = validate.run_scenario("lpv_linf_driver_torque_sector", "track_varying_speed", "model")
    t = r["observer"]
    assert r["status_flags"] == 0
    assert t["beta"]["rms"] < 0.053 and t["beta"]["rms"] == pytest.approx(0.0036, rel=0.1)
    assert t["T_d"]["rms"] == pytest.approx(0.269, rel=0.05)
    assert t["T_d"]["rms"] < 0.25 * 1.1       # the paper's figure, to 10 %


def test_takeover_with_opposing_assistance():
    t = validate.run_scenario("lpv_linf_driver_torque", "takeover_opposing_assist", "model")["observer"]
    assert t["T_d"]["rms"] < 1.5 and t["beta"]["rms"] < 0.1


def test_initial_error_decays(lpv, compiled):
    cfg = observers.get("lpv_linf_driver_torque")
    truth = simulate.nominal_plant(cfg, lpv, common.scenario_for(cfg, "track_varying_speed", 5.0))
    inputs = simulate.observer_input_matrix(compiled.input_names, truth, {})
    wrong = np.array([np.deg2rad(2.0), 0.05, 0.01, 0.1, 5.0])
    out, _, _ = compiled.run(inputs, wrong)
    err_beta = np.abs(out[:, 0] - truth["beta"])
    err_td = np.abs(out[:, 4] - truth["T_d"])
    assert err_beta[0] > np.deg2rad(1.0)
    assert err_beta[300:].max() < np.deg2rad(0.1) and err_td[300:].max() < 2.0


def test_pacejka_truth_plant():
    """Pacejka tyres, load transfer and a trail-based aligning torque: the observer model is wrong now."""
    r = validate.run_scenario("lpv_linf_driver_torque", "takeover_opposing_assist", "nominal")
    assert r["plant_model"] == "steering_single_track_pacejka_plant"
    t = r["observer"]
    # measured: beta 0.009 deg, T_d 0.44 N m (a_y <= 2 m/s^2)
    assert t["beta"]["rms"] < 0.03 and t["T_d"]["rms"] < 0.6
