"""The compiled C step agrees with the CasADi evaluation of the same step (relative 1e-12)."""
import numpy as np
import pytest

from codegen.validation import simulate
from codegen.errors import SampleError
from codegen.validation import common

pytestmark = pytest.mark.slow          # the compiled extension

REL = 1e-12


def _casadi_batch(build, states, inputs):
    f = build.step_function()
    nu, ny = build.lpv.nu, build.lpv.ny
    fm = f.map(states.shape[0])
    z, _ = fm(states.T, inputs[:, :nu].T, inputs[:, nu:nu + ny].T, inputs[:, -1:].T)
    return np.array(z).T


def _rel_err(a, b):
    return np.max(np.abs(a - b), axis=1) / np.maximum(np.max(np.abs(b), axis=1), 1e-300)


def test_random_samples_inside_box(build, compiled):
    rng = np.random.default_rng(2024)
    n = 10000
    states = rng.standard_normal((n, compiled.n_state)) * np.array([0.05, 0.3, 0.1, 0.5, 5.0])
    inputs = np.column_stack([rng.uniform(-5, 5, n), rng.standard_normal((n, 3)) * [0.3, 0.1, 0.5],
                              rng.uniform(build.poly.signal_lower, build.poly.signal_upper, n)])
    ref = _casadi_batch(build, states, inputs)
    got = np.empty_like(ref)
    out = np.empty(compiled.n_output)
    for k in range(n):
        s = states[k].copy()
        assert compiled.step(s, inputs[k], out) == 0
        got[k] = out
        assert np.array_equal(s, out)
    assert _rel_err(got, ref).max() <= REL


def test_full_trajectory(build, lpv, compiled):
    truth = simulate.nominal_plant(build.config, lpv, common.scenario_for(build.config, "track_varying_speed"))
    noisy = simulate.add_sensor_noise(truth, common.SENSOR_NOISE, seed=3)
    inputs = simulate.observer_input_matrix(compiled.input_names, truth, noisy)
    out, status, final = compiled.run(inputs)
    assert not status.any()
    f = build.step_function()
    nu, ny = build.lpv.nu, build.lpv.ny
    acc = f.mapaccum(inputs.shape[0])
    # mapaccum feeds z_next back as z: the CasADi reference of the whole run
    z_all, _ = acc(np.zeros(compiled.n_state), inputs[:, :nu].T, inputs[:, nu:nu + ny].T, inputs[:, -1:].T)
    ref = np.array(z_all).T
    assert _rel_err(out, ref).max() <= 1e-10  # accumulated over 6000 samples
    assert _rel_err(out[:1], ref[:1]).max() <= REL
    np.testing.assert_array_equal(final, out[-1])


def test_bad_samples_have_defined_behaviour(build, compiled):
    bits = compiled.status_bits
    state = np.array([0.01, 0.1, 0.02, 0.0, 1.0])
    out = np.empty(compiled.n_output)
    for bad in (np.nan, np.inf, -np.inf):
        for i in range(compiled.n_input):
            inp = np.array([0.0, 0.1, 0.02, 0.0, 20.0])
            inp[i] = bad
            s = state.copy()
            assert compiled.step(s, inp, out) == bits["NONFINITE_INPUT"]
            np.testing.assert_array_equal(s, state)
            np.testing.assert_array_equal(out, state)
    for speed, clamp_to in ((60.0, 35.0), (1.0, 5.0), (-3.0, 5.0)):
        s = state.copy()
        assert compiled.step(s, np.array([0.0, 0.1, 0.02, 0.0, speed]), out) == bits["SCHEDULING_CLAMPED"]
        s_ref = state.copy()
        assert compiled.step(s_ref, np.array([0.0, 0.1, 0.02, 0.0, clamp_to]), out) == 0
        np.testing.assert_array_equal(s, s_ref)


def test_argument_errors_are_clear(compiled):
    s, out = compiled.initial_state(), np.empty(compiled.n_output)
    with pytest.raises(ValueError, match="inputs must hold 5"):
        compiled.step(s, np.zeros(4), out)
    with pytest.raises(TypeError, match="float64"):
        compiled.step(s, np.zeros(5, dtype=np.float32), out)
    with pytest.raises(TypeError, match="writable|C-contiguous"):
        compiled.step(np.zeros(10)[::2], np.zeros(5), out)
    with pytest.raises(TypeError, match="exactly 3"):
        compiled.step(s, np.zeros(5))
    with pytest.raises(SampleError, match="shape \\(n, 5\\)"):
        compiled.run(np.zeros((10, 4)))
