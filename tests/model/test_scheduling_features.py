"""Model features used by the real-data observer: derived scheduling, several signals, feedthrough."""
import numpy as np
import pytest
import sympy as sp

from codegen.project import observer_file as observers
from codegen.errors import ModelDefinitionError
from codegen.model import ModelDefinition, SchedulingSignal
from codegen.families.linf_uio import build as linf_build
from model_defs.single_track_saturating import secant


def test_secant_is_the_fiala_force_ratio():
    """s(eta) = F/(C alpha) for the Fiala tyre at utilization eta = F/(mu Fz), checked on the force law."""
    f = sp.lambdify(sp.Symbol("y_a_y"), secant.subs({sp.Symbol("mu", positive=True): 1.0,
                                                      sp.Symbol("g", positive=True): 1.0}), "numpy")
    for z in np.linspace(1e-6, 3.0, 200):               # z = C |alpha| / (mu Fz), full slide at 3
        eta = z - z ** 2 / 3 + z ** 3 / 27                # Fiala force / (mu Fz)
        assert f(eta) == pytest.approx(eta / z, rel=1e-9, abs=1e-12)
    assert f(0.0) == 1.0 and f(5.0) == pytest.approx(1 / 3)


def test_derived_signal_may_only_use_outputs_and_parameters():
    x, u, d, v, k, q = sp.symbols("x u d v k q")
    with pytest.raises(ModelDefinitionError, match="may only use parameters, measured outputs"):
        ModelDefinition("bad", (x,), (u,), (d,), sp.Matrix([-k * v * x + u + d]), (("x", x),),
                        (SchedulingSignal(v, derived=q * 2),), (k,))


def test_stanford_polytope_and_step_inputs(built):
    cfg = observers.get("stanford_sideslip")
    lpv, poly, _ = linf_build.representation(cfg)
    assert poly.n_vertices == 8 and len(poly.signals) == 2
    # a_y measures the states *and* the steering angle: output feedthrough of the known input
    assert np.abs(poly.Du).max() > 0
    # exact polytope over the (v_x, s) box: sum eta_i C_i reproduces C(v_x, s) to rounding
    C = sp.lambdify(lpv.scheduling_symbols, lpv.C, "numpy")
    for vx in (15.0, 33.0, 65.0):
        for s in (1 / 3, 0.7, 1.0):
            eta = poly.eta(np.array([vx, s]))
            assert np.allclose(np.einsum("i,ijk->jk", eta, poly.C), np.array(C(vx, s), float), rtol=1e-12, atol=1e-9)
    b = built("stanford_sideslip")
    assert b.input_names == ["delta", "y_r", "y_a_y", "v_x"]      # s is computed inside the step
    assert b.data.quadratic and b.discrete_certificate.kappa > 1


def test_rate_vertices_without_rate_information_do_not_enumerate_corners():
    """rate_bounds = "none": one zero vertex, whatever the vertex count (2^(N-1) corners otherwise)."""
    import dataclasses
    poly = linf_build.representation(observers.get("stanford_sideslip"))[1]
    assert poly.rate_vertices.shape == (1, 8) and not poly.rate_vertices.any()
    big = dataclasses.replace(poly, A=np.zeros((32, 2, 2)), rate_bounds=np.ones((32, 2)))
    from codegen.errors import SchedulingBoundsError
    with pytest.raises(SchedulingBoundsError, match="2\\^31"):
        big.rate_vertices
