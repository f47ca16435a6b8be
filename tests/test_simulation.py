"""It runs and converges: compiled C step vs the exact nonlinear-in-speed plant."""
import numpy as np

from codegen import demo, simulate


def test_converges_on_track_scenario_with_noise():
    r = demo.run_observer("lpv_linf_driver_torque", "track_varying_speed", noise=True)
    t = r["table"]
    assert r["status_nonzero"] == 0
    # seed 000 Table II (SHERPA simulator): beta RMS 0.053 deg, T_d RMS 0.25 N m
    assert t["beta"]["rms"] < 0.03          # deg
    assert t["T_d"]["rms"] < 0.4            # N m
    assert t["T_d"]["max"] < 2.0
    assert t["r"]["rms"] < 0.05             # deg/s


def test_takeover_with_opposing_assistance():
    t = demo.run_observer("lpv_linf_driver_torque", "takeover_opposing_assist", noise=False)["table"]
    assert t["T_d"]["rms"] < 0.15 and t["beta"]["rms"] < 0.01


def test_initial_error_decays(lpv, compiled):
    sim = simulate.simulate_plant(lpv, simulate.SCENARIOS["track_varying_speed"], 0.01)
    inputs = simulate.observer_inputs(lpv, sim)[:500]
    wrong = np.array([np.deg2rad(2.0), 0.05, 0.01, 0.1, 5.0])
    out, _, _ = compiled.run(inputs, wrong)
    err_beta = np.abs(out[:, 0] - sim["x"][:500, 0])
    err_td = np.abs(out[:, 4] - sim["T_d"][:500])
    assert err_beta[0] > np.deg2rad(1.0)
    assert err_beta[300:].max() < np.deg2rad(0.05) and err_td[300:].max() < 1.0
