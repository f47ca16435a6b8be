"""Issue 42 item 8: a TS model whose Jacobian bound does not close its gap within its budget designs
on the sound enclosure reached (a larger DMVT box, not a wrong one), and says so.

The model: a single track with steering and speed premises (the front force's cos(delta) / v and the
yaw rate r) and a magic-formula rear tyre of the unmeasured lateral speed, whose entry
d phi / d v_y is a function of one combination of v_y, r and v over a 3-D box: its branch and bound
stopped at "gap ... after 2001 boxes" and the design was refused.
"""
import numpy as np
import pytest
import sympy as sp

from codegen import pipeline
from codegen.project import observer_file as observers

MODEL = '''
import sympy as sp
from codegen.model import ModelDefinition
v_y, r, v, delta, a_x, Mz = sp.symbols("v_y r v delta a_x Mz")
M, I_z, l_f, l_r, C_f, B, C, D = sp.symbols("M I_z l_f l_r C_f B C D", positive=True)
F_yf = C_f * (delta - (v_y + l_f * r) / v) * sp.cos(delta)
F_yr = D * sp.sin(C * sp.atan(B * (l_r * r - v_y) / v))
MODEL = ModelDefinition(
    name="ts_magic_rear", states=(v_y, r, v), known_inputs=(delta, a_x), unknown_inputs=(Mz,),
    dynamics=sp.Matrix([(F_yf + F_yr) / M - v * r, (l_f * F_yf - l_r * F_yr + Mz) / I_z, a_x + v_y * r]),
    outputs=(("r", r), ("v", v)), scheduling=(), parameters=(M, I_z, l_f, l_r, C_f, B, C, D),
    units={"v_y": "m/s", "r": "rad/s", "v": "m/s", "delta": "rad", "a_x": "m/s^2", "Mz": "N m"})
'''

PARAMS = """[parameters]
M = 1500.0
I_z = 2500.0
l_f = 1.2
l_r = 1.5
C_f = 110000.0
B = 30.0
C = 1.3
D = 3000.0

[state_bounds]
v_y = [-1.5, 1.5]
r = [-0.5, 0.5]
v = [5.0, 40.0]

[inputs]
delta = { min = -0.05, max = 0.05, bandwidth = 0.5 }
a_x = { min = -0.5, max = 0.5, bandwidth = 0.2 }
Mz = { min = -1500.0, max = 1500.0, bandwidth = 0.5 }
"""


def test_a_jacobian_bound_short_of_its_budget_designs_on_its_enclosure(tmp_path):
    (tmp_path / "car.py").write_text(MODEL)
    (tmp_path / "car.toml").write_text(PARAMS)
    obs = tmp_path / "obs.toml"
    obs.write_text('family = "ts_fuzzy_uio"\nmodel = "car.py"\nparameters = "car.toml"\nsample_time = 0.01\n'
                   '[design]\nbounds_max_boxes = 2000\n')
    b = pipeline.build(observers.get(str(obs)))          # refused before: BoundsError "gap ... after 2001 boxes"
    ts = b.ts
    v_y, r, v = ts.definition.states
    delta = ts.definition.known_inputs[0]
    assert {str(p.expr) for p in ts.premises} == {"r", str(sp.cos(delta) / v)}       # steering and speed premises
    assert b.recheck["worst_min_eig"] > 0                  # (27) re-checked on the emitted matrices
    (loose,) = ts.loose_bounds
    assert loose.startswith(f"d({ts.phi[0]})/dv_y: sound enclosure") and "stopped after 2001 boxes" in loose
    assert loose in b.certificate.plant_class
    (entry,) = [e for e in b.artifact()["ts_model"]["jacobian_bounds"][0] if e.get("enclosure")]
    assert entry["state"] == "v_y" and entry["gap"] > 0 and "2001 boxes" in entry["stopped"]
    # the DMVT box the LMIs were solved over holds every Jacobian value of phi in D_x (soundness)
    lo, hi = ts.theta_box[0, 0]
    jac = sp.lambdify((v_y, r, v), sp.diff(ts.phi[0], v_y), "numpy")
    rng = np.random.default_rng(3)
    pts = [rng.uniform(*ts.state_box[s], 20000) for s in (v_y, r, v)]
    values = jac(*pts)
    assert lo <= values.min() and values.max() <= hi
    assert entry["lower"] == pytest.approx(lo, rel=1e-9) and entry["upper"] == pytest.approx(hi, rel=1e-9)
    assert hi - values.max() > 0.01 * (hi - lo)          # looser than the values taken: an enclosure, stated


# A single-track model in (beta, r) with a measured speed state v (the scheduling speed derived from y_v)
# and an unknown yaw moment; its rear tyre law is set by each test.
SIDESLIP = '''
import sympy as sp
from codegen.model import ModelDefinition, SchedulingSignal
beta, r, v, delta, a_x, Mz = sp.symbols("beta r v delta a_x Mz")
v_x = sp.Symbol("v_x", positive=True)
M, I_z, l_f, l_r, C_f, C_r = sp.symbols("M I_z l_f l_r C_f C_r", positive=True)
F_yf = C_f * (delta - beta - l_f * r / v_x)
F_yr = REAR
MODEL = ModelDefinition(
    name="sideslip_derived_speed", states=(beta, r, v), known_inputs=(delta, a_x), unknown_inputs=(Mz,),
    dynamics=sp.Matrix([(F_yf + F_yr) / (M * v_x) - r, (l_f * F_yf - l_r * F_yr + Mz) / I_z, a_x]),
    outputs=(("r", r), ("v", v)),
    scheduling=(SchedulingSignal(v_x, "m/s", derived=sp.Symbol("y_v")),),
    parameters=(M, I_z, l_f, l_r, C_f, C_r),
    units={"beta": "rad", "r": "rad/s", "v": "m/s", "delta": "rad", "a_x": "m/s^2", "Mz": "N m", "v_x": "m/s"})
'''

SIDESLIP_PARAMS = """[parameters]
M = 1500.0
I_z = 2500.0
l_f = 1.2
l_r = 1.5
C_f = 110000.0
C_r = 120000.0

[scheduling.v_x]
min = 5.0
max = 40.0
rate_min = -4.0
rate_max = 4.0

[state_bounds]
beta = [-0.1, 0.1]
r = [-0.5, 0.5]
v = [5.0, 40.0]

[inputs]
delta = { min = -0.03, max = 0.03, bandwidth = 0.5 }
a_x = { min = -0.5, max = 0.5, bandwidth = 0.2 }
Mz = { min = -1500.0, max = 1500.0, bandwidth = 0.5 }
"""


def _project(tmp_path, model, extra=""):
    (tmp_path / "car.py").write_text(model)
    (tmp_path / "car.toml").write_text(SIDESLIP_PARAMS)
    obs = tmp_path / "obs.toml"
    obs.write_text(f'family = "ts_fuzzy_uio"\nmodel = "car.py"\nparameters = "car.toml"\nsample_time = 0.01\n{extra}')
    return obs


def test_a_bound_short_of_its_tolerance_designs_on_its_stated_enclosure(tmp_path):
    """A magic-formula tyre of the unmeasured sideslip, bounded with a budget of one box (issue 42
    item 8): it was refused ("gap ... after 1 boxes"). A sound enclosure short of its tolerance gives
    a larger DMVT box, not a wrong one: the design goes through on it, and the certificate and the
    artifact state that the bound is an enclosure and its gap."""
    model = SIDESLIP.replace("REAR", "3000 * sp.sin(1.3 * sp.atan(C_r * (l_r * r / v_x - beta) / 3900))")
    obs = _project(tmp_path, model, extra="[design]\nbounds_max_boxes = 1\nbounds_rel_tol = 1e-12\n")
    b = pipeline.build(observers.get(str(obs)))
    (loose,) = b.ts.loose_bounds
    assert "/dbeta: sound enclosure" in loose and "gap" in loose and "stopped after" in loose
    assert "not tight within [design] bounds_max_boxes" in b.certificate.plant_class and loose in b.certificate.plant_class
    row = [e for row in b.artifact()["ts_model"]["jacobian_bounds"] for e in row if e.get("enclosure")]
    assert len(row) == 1 and row[0]["state"] == "beta" and row[0]["gap"] > 0
    assert row[0]["lower"] <= row[0]["attained"][0] <= row[0]["attained"][1] <= row[0]["upper"]


def test_a_bound_out_of_reach_names_the_files_boxes(tmp_path):
    """An expression that cannot be enclosed on the box (asin of 20 beta, beta in [-0.1, 0.1]): the
    error names the parameter file's boxes and no [design] budget (which cannot fix it); narrowing
    the box as it says designs."""
    from codegen.errors import BoundsError
    model = SIDESLIP.replace("REAR", "3000 * sp.asin(20 * beta) + C_r * (l_r * r / v_x - beta)")
    obs = _project(tmp_path, model)
    with pytest.raises(BoundsError, match=r"car.toml: .*narrow those of the variables it ranges over "
                                          r"\(observer .*obs.toml\)") as err:
        pipeline.build(observers.get(str(obs)))
    assert "bounds_max_boxes" not in str(err.value) and "bounds_rel_tol" not in str(err.value)
    (tmp_path / "car.toml").write_text(SIDESLIP_PARAMS.replace("beta = [-0.1, 0.1]", "beta = [-0.04, 0.04]"))
    pipeline.build(observers.get(str(obs)))
