"""The switched PI design does not depend on the unknown input's unit (new-user probe F5).

A car towing a trailer, the trailer's lateral hitch force F_t unknown: declared in N (entries of F
~ 1e-3, gamma ~ 2e-6 rad/N) the LMIs failed (Clarabel NumericalError / InsufficientProgress),
declared in kN they certified. A problem that does not solve in the model's units is now solved for
F_t / k, k a power of two committed in the design lock (``ui_scale``), with gamma, P and the gains
reported in the model's units.
"""
import textwrap

import numpy as np
import pytest

from codegen import pipeline
from codegen.design.solver import LockReplay
from codegen.families.switched_pi import design as switched_pi
from codegen.project import observer_file as observers

MODEL = '''
"""Car with trailer: roll-augmented single track; the trailer's lateral hitch force F_t [{unit}] unknown."""
import sympy as sp
from codegen.model import ModelDefinition, SchedulingSignal

beta, r, phi, phi_dot = sp.symbols("beta r phi phi_dot")
delta, F_t = sp.symbols("delta F_t")
v_x = sp.Symbol("v_x", positive=True)
m, m_s, I_x, I_z, l_f, l_r, l_h, h_r, K_r, b_r, C_f, C_r, g = sp.symbols(
    "m m_s I_x I_z l_f l_r l_h h_r K_r b_r C_f C_r g", positive=True)
F_yf = C_f * (delta - beta - l_f * r / v_x)
F_yr = C_r * (l_r * r / v_x - beta)
F_hitch = {newtons} * F_t
a, pdd = sp.symbols("a pdd")
lateral = m * a - m_s * h_r * pdd - (F_yf + F_yr + F_hitch)
roll = (I_x + m_s * h_r ** 2) * pdd - m_s * h_r * a - (m_s * g * h_r * phi - K_r * phi - b_r * phi_dot)
sol = sp.solve([lateral, roll], [a, pdd], dict=True)[0]
MODEL = ModelDefinition(
    name="car_trailer", states=(beta, r, phi, phi_dot), known_inputs=(delta,), unknown_inputs=(F_t,),
    dynamics=sp.Matrix([sp.expand(sol[a] / v_x - r), (l_f * F_yf - l_r * F_yr - l_h * F_hitch) / I_z, phi_dot,
                        sp.expand(sol[pdd])]),
    outputs=(("r", r), ("phi", phi), ("phi_dot", phi_dot)),
    scheduling=(SchedulingSignal(v_x, "m/s"),),
    parameters=(m, m_s, I_x, I_z, l_f, l_r, l_h, h_r, K_r, b_r, C_f, C_r, g),
    units={{"beta": "rad", "r": "rad/s", "phi": "rad", "phi_dot": "rad/s", "delta": "rad", "F_t": "{unit}",
            "v_x": "m/s"}})
'''

PARAMETERS = '''
[parameters]
m = 1093.3
m_s = 965.7
I_x = 207.3
I_z = 1791.6
l_f = 1.156
l_r = 1.423
l_h = 2.4
h_r = 0.614
K_r = 43670.0
b_r = 3252.0
C_f = 128279.0
C_r = 106818.0
g = 9.81

[scheduling.v_x]
min = 5.0
max = 35.0
rate_min = -8.0
rate_max = 4.0

[inputs]
delta = {{ min = -0.02, max = 0.02, bandwidth = 0.5 }}
F_t = {{ min = -{box}, max = {box}, bandwidth = 0.2 }}
'''

OBSERVER = '''
family = "switched_pi"
model = "car_trailer.py"
parameters = "car_trailer.toml"
sample_time = 0.005

[design]
pole_radius = 100.0
decay_rate = 1.0

[switching]
performance = ["beta"]

[[switching.axis]]
name = "v_x"
premise = "v_x"
unit = "m/s"
centres = [10.0, 17.5, 25.0]
points = [{ v_x = 10.0 }, { v_x = 17.5 }, { v_x = 25.0 }]
'''


def _config(folder, unit: str):
    newtons, box = {"N": ("1", "800.0"), "kN": ("1000", "0.8")}[unit]
    folder.mkdir()
    (folder / "car_trailer.py").write_text(MODEL.format(unit=unit, newtons=newtons))
    (folder / "car_trailer.toml").write_text(textwrap.dedent(PARAMETERS.format(box=box)))
    (folder / "trailer_pi.toml").write_text(OBSERVER)
    return observers.get(str(folder / "trailer_pi.toml"))


@pytest.fixture(scope="module")
def designs(tmp_path_factory):
    base = tmp_path_factory.mktemp("trailer")
    out = {}
    for u in ("N", "kN"):
        config = _config(base / u, u)
        out[u] = (config, *pipeline.solve(config))
    return out


def test_unit_power_brings_a_value_into_half_to_one():
    for c, p in [(0.981, 1.0), (0.5606, 1.0), (1.0, 1.0), (0.5, 2.0), (2.17, 0.25), (1.34e-3, 512.0), (2.0, 0.5)]:
        assert switched_pi.unit_power(c) == p
        assert 0.5 < c * p <= 1.0
    assert switched_pi.unit_power(0.0) == 1.0


def test_a_force_in_newtons_certifies_as_it_does_in_kilonewtons(designs):
    """In N the design used to fail (InaccurateSolveError); now it is solved in a power-of-two scale
    and certifies gamma = 0.002157 rad/kN (the optimum the scale reaches). In kN the problem solves
    in the model's units and keeps them (k = 1): its gamma, 0.00238 rad/kN, is the margin's floor, a
    valid bound 10 % above. Each is certified by the numpy re-check and bounds the H-infinity norm
    of the emitted error system."""
    (_, bN, _), (_, bK, _) = designs["N"], designs["kN"]
    assert bN.design.scale[0] > 1e3 and list(bK.design.scale) == [1.0]
    assert bN.design.gamma * 1000 == pytest.approx(0.002157, rel=2e-3)
    assert bN.design.gamma * 1000 <= bK.design.gamma <= 1.15 * bN.design.gamma * 1000
    # the H-infinity norm of the emitted (model-unit) error system, by bisection and by sweep, is within gamma
    for b in (bN, bK):
        assert b.hinf["max_hinf"] <= b.design.gamma
        assert b.recheck["worst_min_eig"] > 0


def test_the_scale_is_a_power_of_two_committed_in_the_lock_and_read_back(designs, monkeypatch):
    config, b, records = designs["N"]
    k = b.design.scale
    assert k.shape == (1,) and np.frexp(k)[0][0] == 0.5 and k[0] > 1e3
    (rec,) = records
    assert rec.data == {"ui_scale": [float(k[0])]}
    # gamma in the model's units is the solver's gamma / k, exactly
    assert b.design.gamma == pytest.approx(np.sqrt(rec.variables["gamma2"]) / k[0], rel=1e-11)
    # a replay reads k from the lock, not from the rule
    monkeypatch.setattr(switched_pi, "ui_scale", lambda sm: pytest.fail("the replay re-derived the scale"))
    again = pipeline.build(config, LockReplay(records, "lock"))
    assert again.design.ui_scale == b.design.ui_scale and again.design.gamma == b.design.gamma
    for i in range(3):
        np.testing.assert_array_equal(again.design.KI[i], b.design.KI[i])
    np.testing.assert_array_equal(again.design.P, b.design.P)


def test_a_lock_with_a_scale_that_is_not_a_power_of_two_is_refused(designs):
    from codegen.errors import DesignLockError
    import dataclasses
    config, _, records = designs["N"]
    bad = [dataclasses.replace(records[0], data={"ui_scale": [1000.0]})]
    with pytest.raises(DesignLockError, match="power"):
        pipeline.build(config, LockReplay(bad, "lock"))


def test_a_committed_solution_without_a_scale_was_solved_in_the_model_units():
    """A lock or gains file from before the scale has no ``ui_scale``: it is replayed at k = 1 (what it
    was solved at), and a fresh design records k only when it is not 1."""
    from codegen.design.lmi import SolveRecord
    from codegen.families.switched_pi import representation as switched
    from codegen.model import load_parameters
    config = observers.get("switched_pi_bank_angle")
    sm = switched.build(config.design_model(), load_parameters(config.parameter_path), config.switching)
    name = switched_pi.problem_name(sm)
    old = SolveRecord(name, {}, 0.0, 0, {})
    assert list(switched_pi.solver_scale(sm, None, None, LockReplay([old], "lock"))) == [1.0]
    T, _ = switched_pi.decoupling_matrices(sm.C[0])
    settings = switched_pi.SwitchedPIDesignSettings()
    assert switched_pi.build_problem(sm, T, settings, [1.0]).data == {}
    assert switched_pi.build_problem(sm, T, settings, [64.0]).data == {"ui_scale": [64.0]}
