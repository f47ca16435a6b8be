"""Kalman baselines generated from symbolic models (codegen.validation.kalman, model_defs.baselines)."""
import casadi as ca
import numpy as np
import pytest
import sympy as sp

from codegen.errors import ModelDefinitionError, SampleError
from codegen.model import ModelDefinition, SchedulingSignal
from codegen.validation import kalman
from codegen.validation.peers import STANFORD_CAR
from model_defs import baselines
from model_defs import single_track_saturating as observer_model

VALUES = {**STANFORD_CAR.values(), "mu": 1.7, "g": 9.81}


def test_linear_model_is_the_observer_model_with_linear_tyres():
    sub = {observer_model.s: 1, observer_model.M_z: 0}
    assert baselines.LINEAR_SINGLE_TRACK.dynamics == observer_model.MODEL.dynamics.subs(sub)
    assert dict(baselines.LINEAR_SINGLE_TRACK.outputs)["a_y"] == dict(observer_model.MODEL.outputs)["a_y"].subs(sub)


@pytest.mark.parametrize("vx", [16.0, 37.5, 61.0])
def test_linear_matrices_equal_the_source_repository(vx):
    # BetaStanfordLinear.m (source repository of the data), written out independently here
    m, lf, lr, iz, cf, cr = (STANFORD_CAR.m, STANFORD_CAR.lf, STANFORD_CAR.lr, STANFORD_CAR.iz,
                             STANFORD_CAR.cf, STANFORD_CAR.cr)
    A = np.array([[-(cf + cr) / (m * vx), -1 - (lf * cf - lr * cr) / (m * vx ** 2)],
                  [-(lf * cf - lr * cr) / iz, -(lf ** 2 * cf + lr ** 2 * cr) / (iz * vx)]])
    B = np.array([[cf / (m * vx)], [lf * cf / iz]])
    C = np.array([[-(cf + cr) / m, -(lf * cf - lr * cr) / (m * vx)], [0.0, 1.0]])
    D = np.array([[cf / m], [0.0]])
    model = kalman.kalman_model(baselines.LINEAR_SINGLE_TRACK, VALUES, outputs=("a_y", "r"),
                                noisy_inputs=("delta",))
    assert model.linear and model.states == ("beta", "r") and model.noise == ("delta",)
    A_, B_, G_, C_, D_ = model.matrices(vx)
    for got, want in ((A_, A), (B_, B), (G_, B), (C_, C), (D_, D)):
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13)


def test_fiala_force_slope_saturation_continuity():
    alpha = sp.Symbol("alpha", real=True)
    c, mu_fz = 7e4, 5000.0
    x = ca.SX.sym("a")
    f = kalman.to_casadi([baselines.fiala_axle_force(alpha, c, mu_fz)], [alpha], [x])[0]
    fn = ca.Function("fiala", [x], [f, ca.jacobian(f, x)])
    val, slope = (float(v) for v in fn(0.0))
    assert val == 0.0 and slope == pytest.approx(c)
    for a in (0.5, -0.5):                                  # full sliding: mu F_z, zero slope
        val, slope = (float(v) for v in fn(a))
        assert val == pytest.approx(np.sign(a) * mu_fz) and slope == 0.0
    a_sl = np.arctan(3 * mu_fz / c)                        # continuous at the sliding limit
    assert float(fn(a_sl - 1e-9)[0]) == pytest.approx(mu_fz, rel=1e-9)
    assert float(fn(a_sl - 1e-9)[1]) == pytest.approx(0.0, abs=1e-3)
    # odd and increasing below the limit
    grid = np.linspace(-a_sl, a_sl, 101)
    vals = np.array([float(fn(a)[0]) for a in grid])
    assert np.all(np.diff(vals) > 0) and np.allclose(vals, -vals[::-1])


def test_ekf_jacobians_match_finite_differences():
    model = kalman.kalman_model(baselines.FIALA_SINGLE_TRACK, VALUES, outputs=("a_y", "r"))
    assert not model.linear and model.noise == ("w_f", "w_r")
    rng = np.random.default_rng(3)
    for _ in range(20):
        x = rng.normal([0.0, 0.0], [1.0, 0.4])
        u, rho, eps = rng.normal(0.0, 0.05, 1), rng.uniform(16.0, 61.0, 1), 1e-6
        A, B, G, C, D = (np.array(m.full()) for m in model.jacobians(x, u, rho))

        def fd(fun, at, k):
            e = np.zeros_like(at)
            e[k] = eps
            return (np.array(fun(at + e).full()).ravel() - np.array(fun(at - e).full()).ravel()) / (2 * eps)
        w0 = np.zeros(2)
        for k in range(2):
            np.testing.assert_allclose(A[:, k], fd(lambda z: model.f(z, u, w0, rho), x, k), rtol=1e-5, atol=1e-4)
            np.testing.assert_allclose(G[:, k], fd(lambda w: model.f(x, u, w, rho), w0, k), rtol=1e-5, atol=1e-4)
            np.testing.assert_allclose(C[:, k], fd(lambda z: model.h(z, u, rho), x, k), rtol=1e-5, atol=1e-4)
        np.testing.assert_allclose(B[:, 0], fd(lambda v: model.f(x, v, w0, rho), u, 0), rtol=1e-5, atol=1e-3)
        np.testing.assert_allclose(D[:, 0], fd(lambda v: model.h(x, v, rho), u, 0), rtol=1e-5, atol=1e-3)


def _constant_model():
    c = sp.Symbol("c")
    return ModelDefinition(name="constant", states=(c,), known_inputs=(), unknown_inputs=(),
                           dynamics=sp.Matrix([0]), outputs=(("y", c),), scheduling=(), parameters=())


def test_linear_filter_is_the_exact_recursive_mean():
    # estimating a constant from y = c + noise: P_n = 1/(1/P0 + n/s^2), x_n = sum(y)/(n + s^2/P0)
    model = kalman.kalman_model(_constant_model(), {})
    y = np.random.default_rng(0).normal(2.0, 0.3, 400)
    s2, p0 = 0.09, 4.0
    res = kalman.linear_kalman_filter(model, np.zeros((400, 0)), y, np.zeros((400, 0)), 0.01, R=[[s2]],
                                      Sigma=np.zeros((0, 0)), x0=[0.0], P0=[[p0]])
    n = np.arange(400)                                     # measurements used at sample k: y[1..k]
    cum = np.concatenate([[0.0], np.cumsum(y[1:])])
    np.testing.assert_allclose(res.x[:, 0], cum / (n + s2 / p0), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(res.P[:, 0, 0], 1 / (1 / p0 + n / s2), rtol=1e-10)


def test_errors_are_typed():
    fiala = kalman.kalman_model(baselines.FIALA_SINGLE_TRACK, VALUES)
    sig = dict(dt=0.01, R=np.eye(2), Sigma=np.eye(2), x0=np.zeros(2), P0=np.eye(2))
    n = 5
    with pytest.raises(ModelDefinitionError, match="not linear"):
        kalman.linear_kalman_filter(fiala, np.zeros(n), np.zeros((n, 2)), np.full(n, 20.0), **sig)
    with pytest.raises(ModelDefinitionError, match="mu"):
        kalman.kalman_model(baselines.FIALA_SINGLE_TRACK, STANFORD_CAR.values())
    with pytest.raises(ModelDefinitionError, match="outputs"):
        kalman.kalman_model(baselines.FIALA_SINGLE_TRACK, VALUES, outputs=("beta",))
    with pytest.raises(ModelDefinitionError, match="noisy input"):
        kalman.kalman_model(baselines.FIALA_SINGLE_TRACK, VALUES, noisy_inputs=("v_x",))
    c = sp.Symbol("c")
    signed = ModelDefinition(name="signed", states=(c,), known_inputs=(), unknown_inputs=(),
                             dynamics=sp.Matrix([sp.sign(c)]), outputs=(("y", c),), scheduling=(), parameters=())
    with pytest.raises(ModelDefinitionError, match="CasADi"):
        kalman.kalman_model(signed, {})
    with pytest.raises(SampleError, match="measurements"):
        kalman.extended_kalman_filter(fiala, np.zeros(n), np.zeros((n, 3)), np.full(n, 20.0), **sig)
    with pytest.raises(SampleError, match="non-finite"):
        kalman.extended_kalman_filter(fiala, np.zeros(n), np.full((n, 2), np.nan), np.full(n, 20.0), **sig)
    with pytest.raises(ModelDefinitionError, match="R must"):
        kalman.extended_kalman_filter(fiala, np.zeros(n), np.zeros((n, 2)), np.full(n, 20.0),
                                      **{**sig, "R": -np.eye(2)})
    derived = ModelDefinition(name="derived", states=(c,), known_inputs=(), unknown_inputs=(),
                              dynamics=sp.Matrix([-c]), outputs=(("y", c),),
                              scheduling=(SchedulingSignal(sp.Symbol("s"), derived=sp.Symbol("y_y") ** 2),),
                              parameters=())
    with pytest.raises(ModelDefinitionError, match="derived"):
        kalman.kalman_model(derived, {})
