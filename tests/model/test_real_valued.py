"""Every signal is real: sympy's conjugate/re/im of symbols declared without ``real=True`` are read as the
identities they are for real values (codegen/model/real.py), so a user's own tyre law never reaches a stage
as a function nothing can evaluate (it was a NameError traceback in design and in the Kalman peers)."""
import numpy as np
import sympy as sp

from codegen.model import ModelDefinition, SchedulingSignal
from codegen.model.real import real_valued
from codegen.validation import kalman
from model_defs import tyres


def _load_sensitive_model():
    """A single-track model with longitudinal load transfer and a load-sensitive stiffness, its symbols
    declared as most users declare them (no ``real=True``)."""
    v_y, r, delta, a_x = sp.symbols("v_y r delta a_x")
    v_x = sp.Symbol("v_x", positive=True)
    m, l, C, mu, g, I_z = sp.symbols("m l C mu g I_z", positive=True)
    h, c = sp.symbols("h c")
    F_z = m * (g - h * a_x) / 2
    t = delta - (v_y + l * r) / v_x
    F = tyres.fiala_slip_force(t, C * (1 + c * (F_z / (m * g / 2) - 1)), mu * F_z)
    return ModelDefinition(name="load_sensitive", states=(v_y, r), known_inputs=(delta, a_x), unknown_inputs=(),
                           dynamics=sp.Matrix([F / m - r * v_x, l * F / I_z]), outputs=(("a_y", F / m), ("r", r)),
                           scheduling=(SchedulingSignal(v_x, "m/s"),), parameters=(m, l, C, mu, g, I_z, h, c)), F


def test_conjugate_of_undeclared_real_symbols_is_read_as_the_real_value():
    model, raw = _load_sensitive_model()
    assert raw.has(sp.conjugate)                      # what sympy builds from these declarations
    assert not any(e.has(sp.conjugate, sp.re, sp.im) for e in (*model.dynamics, *(e for _, e in model.outputs)))
    values = {"m": 1500.0, "l": 1.3, "C": 90000.0, "mu": 1.0, "g": 9.81, "I_z": 2500.0, "h": 0.5, "c": 0.8}
    subs = {s: values[str(s)] for s in model.parameters}
    rng = np.random.default_rng(3)
    for _ in range(40):             # beyond sliding as well: |t| up to 0.4 rad against t_sl near 0.1
        point = dict(zip((*model.states, *model.known_inputs, model.scheduling[0].symbol),
                         (rng.uniform(-3, 3), rng.uniform(-1, 1), rng.uniform(-0.2, 0.2), rng.uniform(-8, 6),
                          rng.uniform(10, 40))))
        a_raw = complex(sp.N((raw / subs[sp.Symbol("m", positive=True)]).xreplace({**subs, **point})))
        a_read = float(sp.N(dict(model.outputs)["a_y"].xreplace({**subs, **point})))
        assert abs(a_raw.imag) < 1e-9 and abs(a_raw.real - a_read) <= 1e-9 * max(1.0, abs(a_read))


def test_the_kalman_peers_evaluate_such_a_model():
    model, _ = _load_sensitive_model()
    values = {"m": 1500.0, "l": 1.3, "C": 90000.0, "mu": 1.0, "g": 9.81, "I_z": 2500.0, "h": 0.5, "c": 0.8}
    km = kalman.kalman_model(model, values, outputs=("a_y", "r"))
    x_dot = np.array(km.f(np.array([0.3, 0.1]), np.array([0.02, -4.0]), np.zeros(0), np.array([25.0]))).ravel()
    assert np.all(np.isfinite(x_dot))


def test_real_valued_keeps_expressions_without_them_object_for_object():
    x = sp.Symbol("x")
    e = sp.Abs(x) * x + 1
    assert real_valued(e) is e
    assert real_valued(sp.re(x) + sp.im(x) + sp.conjugate(x)) == 2 * x
