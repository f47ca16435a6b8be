"""A model of one state: every family that takes it designs it (a 1x1 Lyapunov matrix stays a matrix:
the LMI solution handed a 1x1 symmetric variable back as a number, and analyze, `new --from-model` and
design ended in an AttributeError traceback)."""
import json
import textwrap

import numpy as np

from codegen import cli
from codegen.design.lmi import LMIProblem

MODEL = textwrap.dedent('''
    """Yaw rate with an unknown yaw moment (one state)."""
    import sympy as sp
    from codegen.model import ModelDefinition, SchedulingSignal
    r, delta, M = sp.symbols("r delta M")
    v_x = sp.Symbol("v_x", positive=True)
    I_z, C_f, l_f, c_r = sp.symbols("I_z C_f l_f c_r", positive=True)
    MODEL = ModelDefinition(name="one_state", states=(r,), known_inputs=(delta,), unknown_inputs=(M,),
                            dynamics=sp.Matrix([(-c_r * r / v_x + l_f * C_f * delta + M) / I_z]),
                            outputs=(("r", r),), scheduling=(SchedulingSignal(v_x, "m/s"),),
                            parameters=(I_z, C_f, l_f, c_r),
                            units={"r": "rad/s", "delta": "rad", "M": "N m", "v_x": "m/s", "I_z": "kg m^2",
                                   "C_f": "N/rad", "l_f": "m", "c_r": "N m^2"})
''')
PARAMETERS = textwrap.dedent('''
    [parameters]
    I_z = 2500.0
    C_f = 90000.0
    l_f = 1.2
    c_r = 400000.0

    [scheduling.v_x]
    min = 5.0
    max = 40.0
    rate_min = -5.0
    rate_max = 5.0

    [state_bounds]
    delta = [-0.1, 0.1]

    [inputs]
    delta = { min = -0.05, max = 0.05, bandwidth = 0.5 }
    M = { min = -500.0, max = 500.0, bandwidth = 0.3 }
''')


def test_a_one_by_one_matrix_variable_stays_a_matrix_and_a_scalar_a_number():
    prob = LMIProblem("one")
    P = prob.symmetric("P", 1)
    t = prob.scalar("t")
    prob.require_psd("P>=I", P, margin=1.0)
    prob.require_psd("t>=P", t - P)
    prob.minimize(t)
    sol = prob.solve(tol=1e-8)
    assert np.shape(sol["P"]) == (1, 1) and isinstance(sol["t"], float)


def test_every_family_that_takes_a_one_state_model_designs_it(tmp_path, capsys):
    (tmp_path / "one.py").write_text(MODEL)
    (tmp_path / "one.toml").write_text(PARAMETERS)
    model, params = str(tmp_path / "one.py"), str(tmp_path / "one.toml")
    assert cli.main(["analyze", model, "--parameters", params, "--json"]) == 0
    ranking = json.loads(capsys.readouterr().out)["ranking"]
    applying = [f for f in ranking["families"] if f["applies"]]
    assert len(applying) >= 3              # the decoupling, box-gain and switched families take it
    for entry in applying:
        figures = entry["trial"]["figures"]
        assert 0 < figures["contraction_per_step"]["value"] < 1, entry["family"]
        folder = tmp_path / entry["family"]
        assert cli.main(["new", str(folder), "--from-model", model, "--parameters", params,
                         "--family", entry["family"]]) == 0
        capsys.readouterr()
        (observer,) = folder.glob("*.toml")
        assert cli.main(["design", str(observer), "--json"]) == 0, entry["family"]
        assert json.loads(capsys.readouterr().out)
