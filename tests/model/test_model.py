"""Model layer: the Nguyen et al. 2019 equations come out as eq. (5), and bad definitions fail precisely."""
import re
import textwrap

import numpy as np
import pytest
import sympy as sp

from codegen.errors import (MissingParameterError, ModelDefinitionError, NotAffineError,
                            SchedulingBoundsError, UnknownParameterError)
from codegen.model import ModelDefinition, SchedulingSignal, instantiate, load_parameters
from model_defs.steering_single_track import MODEL

TABLE1 = dict(l_f=1.3, l_r=1.6, eta_t=0.13, R_s=16.0, B_s=5.73, K_p=0.5, M=2052.0, I_z=2800.0,
              I_s=0.05, C_f=57000.0, C_r=59000.0)


def paper_A(vx):
    """Eq. (4)-(5) of Nguyen et al. 2019, typed from the paper independently of the symbolic model."""
    return paper_A_w(1 / vx, 1 / vx ** 2)


def paper_A_w(w, w2):
    """A of eq. (5) as a function of w = 1/v_x and w2 = 1/v_x^2 (independently typed)."""
    p = TABLE1
    vx = 1 / w
    Tsb = 2 * p["K_p"] * p["C_f"] * p["eta_t"] / p["R_s"]
    Tsr = 2 * p["K_p"] * p["C_f"] * p["eta_t"] * p["l_f"] / (p["R_s"] * vx)
    a11 = -2 * (p["C_r"] + p["C_f"]) / (p["M"] * vx)
    a12 = 2 * (p["l_r"] * p["C_r"] - p["l_f"] * p["C_f"]) * w2 / p["M"] - 1
    a21 = 2 * (p["l_r"] * p["C_r"] - p["l_f"] * p["C_f"]) / p["I_z"]
    a22 = -2 * (p["l_r"] ** 2 * p["C_r"] + p["l_f"] ** 2 * p["C_f"]) / (p["I_z"] * vx)
    b1, b2 = 2 * p["C_f"] / (p["M"] * vx), 2 * p["l_f"] * p["C_f"] / p["I_z"]
    RI = p["R_s"] * p["I_s"]
    return np.array([[a11, a12, b1, 0], [a21, a22, b2, 0], [0, 0, 0, 1],
                     [Tsb / RI, Tsr / RI, -Tsb / RI, -p["B_s"] / p["I_s"]]])


def test_lpv_matrices_match_paper(lpv):
    vx = sp.Symbol("v_x", positive=True)
    A = sp.lambdify(vx, lpv.A, "numpy")
    for v in np.linspace(5, 35, 13):
        np.testing.assert_allclose(np.array(A(v), float), paper_A(v), rtol=1e-13, atol=1e-13)
    RI = TABLE1["R_s"] * TABLE1["I_s"]
    np.testing.assert_allclose(np.array(lpv.B, float).ravel(), [0, 0, 0, 1 / RI])
    np.testing.assert_allclose(np.array(lpv.D, float).ravel(), [0, 0, 0, 1 / RI])
    np.testing.assert_array_equal(np.array(lpv.C, float), [[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    assert lpv.parameters.scheduling["v_x"].lower == 5.0 and lpv.boxes[0].rate_upper == 4.0


def _write(tmp_path, body):
    path = tmp_path / "p.toml"
    path.write_text(textwrap.dedent(body))
    return path


BASE = """
[parameters]
{params}
[scheduling.v_x]
min = 5.0
max = 35.0
rate_min = -4.0
rate_max = 4.0
"""


def _params_text(drop=None, extra=""):
    return "\n".join(f"{k} = {v}" for k, v in TABLE1.items() if k != drop) + "\n" + extra


def test_missing_parameter_names_it(tmp_path):
    path = _write(tmp_path, BASE.format(params=_params_text(drop="C_r")))
    with pytest.raises(MissingParameterError, match="C_r"):
        instantiate(MODEL, load_parameters(path))


def test_unknown_parameter_is_refused(tmp_path):
    path = _write(tmp_path, BASE.format(params=_params_text(extra="C_rr = 1.0")))
    with pytest.raises(UnknownParameterError, match="C_rr"):
        instantiate(MODEL, load_parameters(path))


def test_scheduling_without_bounds(tmp_path):
    path = _write(tmp_path, "[parameters]\n" + _params_text())
    with pytest.raises(SchedulingBoundsError, match="v_x"):
        instantiate(MODEL, load_parameters(path))
    bad = _write(tmp_path, BASE.format(params=_params_text()).replace("max = 35.0", "max = 1.0"))
    with pytest.raises(SchedulingBoundsError, match="min < max"):
        load_parameters(bad)
    missing_rate = _write(tmp_path, BASE.format(params=_params_text()).replace("rate_max = 4.0", ""))
    with pytest.raises(SchedulingBoundsError, match="rate_max"):
        load_parameters(missing_rate)


def test_non_numeric_parameter(tmp_path):
    path = _write(tmp_path, BASE.format(params=_params_text(extra='oops = "x"')))
    with pytest.raises(ModelDefinitionError, match="oops"):
        load_parameters(path)


def _toy(dynamics, outputs=None, scheduling=True):
    x1, x2, u, d, v, k = sp.symbols("x1 x2 u d v k")
    return ModelDefinition("toy", (x1, x2), (u,), (d,), dynamics(x1, x2, u, d, v, k),
                           outputs or (("x1", x1),), (SchedulingSignal(v),) if scheduling else (), (k,))


def test_non_affine_dynamics_rejected(tmp_path):
    model = _toy(lambda x1, x2, u, d, v, k: sp.Matrix([x2, -k * x1 ** 3 / v + u + d]))
    path = _write(tmp_path, "[parameters]\nk = 1.0\n[scheduling.v]\nmin=1\nmax=2\nrate_min=-1\nrate_max=1\n")
    with pytest.raises(NotAffineError, match="not affine in the states"):
        instantiate(model, load_parameters(path))


def test_a_long_non_affine_derivative_is_cut_short_in_the_message(tmp_path):
    """A user's tyre law differentiates to thousands of characters (13,609 for a rational law of the
    wheel-frame slip): the message keeps its head, its length and the symbols it depends on."""
    law = lambda x1, x2, u, d, v, k: sp.Matrix([x2, sum(sp.atan(k * x1 / (v + j)) / (1 + sp.Abs(x1 - j))
                                                         for j in range(12)) + u + d])
    path = _write(tmp_path, "[parameters]\nk = 1.0\n[scheduling.v]\nmin=1\nmax=2\nrate_min=-1\nrate_max=1\n")
    with pytest.raises(NotAffineError, match="not affine in the states") as exc:
        instantiate(_toy(law), load_parameters(path))
    msg = str(exc.value)
    assert re.search(r"\.\.\. \(\d{3,} characters\) still depends on x1", msg) and len(msg) < 400


def test_wrong_shape_and_undeclared_symbols():
    with pytest.raises(ModelDefinitionError, match="column of 2"):
        _toy(lambda x1, x2, u, d, v, k: sp.Matrix([x2]))
    with pytest.raises(ModelDefinitionError, match="undeclared symbol"):
        _toy(lambda x1, x2, u, d, v, k: sp.Matrix([x2, sp.Symbol("zeta") * x1]))


def test_an_output_that_reads_no_state_is_refused_naming_it():
    """Issue 42: an output that reads no state (a known input, an unknown input, a constant) was
    accepted silently; it tells the observer nothing about the states. Refused, naming the output;
    written in the state it measures, the model is accepted."""
    x1, x2, u, d = sp.symbols("x1 x2 u d")

    def model(outputs):
        return ModelDefinition("no_state_output", (x1, x2), (u,), (d,), sp.Matrix([x2, -x1 - x2 + u + d]),
                               outputs, (), ())
    for expr, what in ((u, "it reads only u"), (2 * d, "it reads only d"), (sp.Integer(3), "it is a constant")):
        with pytest.raises(ModelDefinitionError, match=rf"output 'a' = .* reads no state \({what}\)"):
            model((("y", x1), ("a", expr)))
    assert model((("y", x1), ("a", x2 + u))).output_names == ("y", "a")


# -- numbers that differ only by rounding are one number (issue 42, item 6) ---------------------------
def test_floats_of_rounding_noise_are_merged_and_others_kept():
    from codegen.model.floats import FLOAT_NOISE, merge_float_noise
    x = sp.Symbol("x")
    a, b = sp.tanh(sp.Float(12.5) * x), sp.tanh(sp.Float(12.500000000000002) * x)
    merged = merge_float_noise([a, b, sp.Float(12.5 * (1 + 10 * FLOAT_NOISE)) * x])
    assert merged[0] == merged[1] == a                      # 2 ulps apart: one law
    assert merged[2] != sp.Float(12.5) * x                   # 1e-11 apart: two numbers, kept
    neg = merge_float_noise([sp.Float(-0.3) * x, sp.Float(-0.30000000000000004) * x])
    assert neg[0] == neg[1] == sp.Float(-0.30000000000000004) * x      # the smallest of the cluster


def test_a_nonlinearity_written_twice_by_sp_solve_is_one_premise(tmp_path):
    """sp.solve writes one factor 1/(v_x + 0.5) in two rows with coefficients that differ in the last
    digit: one premise (2 vertices), not two (4)."""
    from codegen.model import ParameterSet, SchedulingBox
    from codegen.representation import polytope
    x1, x2, d, v = sp.symbols("x1 x2 d v_x")
    f = sp.Matrix([-x1 / (sp.Float(0.1) * v + 1) + x2, -x2 / (sp.Float(0.1 + 1e-17 * 2 ** 4) * v + 1) + d])
    assert f[0].atoms(sp.Float) != f[1].atoms(sp.Float)
    model = ModelDefinition("solved", (x1, x2), (), (d,), f, (("x1", x1),), (SchedulingSignal(v),), ())
    lpv = instantiate(model, ParameterSet("p", {}, {"v_x": SchedulingBox("v_x", 5.0, 40.0, -1.0, 1.0)}, {}))
    assert len(polytope.scheduling_nonlinearities(lpv)) == 1
    assert polytope.sector_polytope(lpv).n_vertices == 2
