"""The nonlinear-tyre family takes a user's own names: every signal of the observer (states,
known inputs, measured outputs, the forward speed) is named by the model, its unit is the model's,
the speed's box is read from ``[scheduling.<the model's speed>]``, and the roles the family needs
(which output is the lateral acceleration, which the yaw rate, which known input the steering
angle) are read from the model's structure, or refused naming the role and how to declare it.

The model below renames everything the built-in one has (v_y, r, delta, a_x, a_y, v_x), lists the
known inputs with the steering angle second and the outputs with the yaw rate first.
"""
import json
import re

import numpy as np
import pytest

from codegen import cli, families, pipeline
from codegen.design.solver import FreshSolver
from codegen.errors import ModelDefinitionError, SchedulingBoundsError
from codegen.project import observer_file as observers

FAMILY = families.get("nonlinear_tyre_observer")

MODEL = '''
"""Single track, a tanh tyre per axle whose capacity the measured longitudinal acceleration lowers."""
import sympy as sp
from codegen.model import Axle, ModelDefinition, SchedulingSignal

vlat, yawr = sp.symbols("vlat yawr")
steer, ax_meas = sp.symbols("steer ax_meas")
wf, wr = sp.symbols("wf wr")
spd = sp.Symbol("spd", positive=True)
m, a, b, Jz, Cf, Cr, muf, mur, g = sp.symbols("m a b Jz Cf Cr muf mur g", positive=True)
t_sym = sp.Symbol("t", real=True)
F_PEAK = sp.symbols("Fpk_f Fpk_r", positive=True)
L = a + b
Fzf = m * g * b / L
Fzr = m * g * a / L
cap_f = sp.sqrt((muf * Fzf) ** 2 - (m * ax_meas * b / L) ** 2)
cap_r = sp.sqrt((mur * Fzr) ** 2 - (m * ax_meas * a / L) ** 2)
tf = sp.tan(steer - sp.atan((vlat + a * yawr) / spd))
tr = (b * yawr - vlat) / spd


def law(t, C, Fp):
    return Fp * sp.tanh(C * t / Fp)


Phi_f = law(tf, Cf, cap_f) * sp.cos(steer) + Fzf * wf
Phi_r = law(tr, Cr, cap_r) + Fzr * wr
FORCES = sp.symbols("Phi_f Phi_r")
A_Y_IN_FORCES = (FORCES[0] + FORCES[1]) / m
DYNAMICS_IN_FORCES = sp.Matrix([A_Y_IN_FORCES - yawr * spd, (a * FORCES[0] - b * FORCES[1]) / Jz])
_forces = {FORCES[0]: Phi_f, FORCES[1]: Phi_r}


AXLES = (
    Axle("front", law(t_sym, Cf, F_PEAK[0]), sp.cos(steer), tf,
         spd * (sp.sin(steer) - t_sym * sp.cos(steer)) / (sp.cos(steer) + t_sym * sp.sin(steer)) - a * yawr,
         3 * F_PEAK[0] / Cf, F_PEAK[0], cap_f, Cf, muf),
    Axle("rear", law(t_sym, Cr, F_PEAK[1]), sp.Integer(1), tr, b * yawr - spd * t_sym,
         3 * F_PEAK[1] / Cr, F_PEAK[1], cap_r, Cr, mur),
)
MODEL = ModelDefinition(
    name="tanh_hatchback", states=(vlat, yawr), known_inputs=(ax_meas, steer), unknown_inputs=(wf, wr),
    dynamics=DYNAMICS_IN_FORCES.subs(_forces),
    outputs=(("gyro", yawr), ("lat_acc", A_Y_IN_FORCES.subs(_forces))),
    scheduling=(SchedulingSignal(spd, "m/s"),),
    parameters=(m, a, b, Jz, Cf, Cr, muf, mur, g),
    units={"vlat": "m/s", "yawr": "rad/s", "steer": "rad", "ax_meas": "m/s^2", "wf": "-", "wr": "-",
           "lat_acc": "m/s^2", "gyro": "rad/s"})
'''

PARAMS = """[parameters]
m = 1250.0
a = 1.05
b = 1.55
Jz = 1700.0
Cf = 90000.0
Cr = 85000.0
muf = 0.95
mur = 0.95
g = 9.81

[scheduling.spd]
min = 8.0
max = 40.0
rate_min = -8.0
rate_max = 4.0

[state_bounds]
steer = [-0.15, 0.15]
ax_meas = [-2.0, 2.0]

[inputs]
steer = { min = -0.02, max = 0.02, bandwidth = 0.5 }
ax_meas = { min = -1.0, max = 1.0, bandwidth = 0.2 }
wf = { min = 0.0, max = 0.0 }
wr = { min = 0.0, max = 0.0 }
"""

OBSERVER = """family = "nonlinear_tyre_observer"
model = "tanh_car.py"
parameters = "hatch.toml"
sample_time = 0.01

[design]
stiffness_range = [0.9, 1.1]
friction_range = [0.9, 1.1]
sigma_force_front = 300.0
sigma_force_rear = 300.0
sigma_ay = 0.5
"""

INPUTS = ["ax_meas", "steer", "y_gyro", "y_lat_acc", "spd"]
UNITS = {"ax_meas": "m/s^2", "steer": "rad", "y_gyro": "rad/s", "y_lat_acc": "m/s^2", "spd": "m/s"}


def project(folder, model=MODEL, params=PARAMS, extra=""):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "tanh_car.py").write_text(model)
    (folder / "hatch.toml").write_text(params)
    path = folder / "obs.toml"
    path.write_text(OBSERVER + extra)
    return path


@pytest.fixture(scope="module")
def renamed(tmp_path_factory):
    path = project(tmp_path_factory.mktemp("renamed"))
    config = observers.get(str(path))
    return config, FAMILY.build(config, FreshSolver())


def test_every_signal_is_named_by_the_model_with_its_unit(renamed):
    from codegen.emit.generate import render, signal_fields
    from codegen.emit.header import unit_of
    config, b = renamed
    assert b.state_names == ["vlat_next", "yawr_next", "vlat", "yawr"]
    assert b.output_names == ["vlat", "yawr"]
    assert b.input_names == INPUTS                  # known inputs, outputs (model order), the speed
    assert (b.nu, b.ny) == (2, 2)
    assert b.scheduling_boxes() == [("spd", 8.0, 40.0, False)]
    assert set(b.input_boxes()) == {"spd", "ax_meas", "steer"}
    assert set(b.certificate.region) == {"spd", "ax_meas", "steer"}
    # the C API's fields (what the runtime, the header and the FMU read), units from the model
    state, inputs, outputs = signal_fields(b, b.step_function())
    assert {f["name"]: unit_of(f["doc"]) for f in inputs} == UNITS
    assert {f["name"]: unit_of(f["doc"]) for f in outputs} == {"vlat": "m/s", "yawr": "rad/s"}
    header = render(b, lock_text="{}")["obs.h"]
    fields = set(re.findall(r"\b(?:double|int32_t)\s+(\w+);", header))
    assert set(INPUTS) | {"vlat", "yawr"} <= fields, fields
    assert not {"v_x", "v_y", "r", "delta", "y_r", "y_a_y", "a_x"} & fields, fields
    assert "vlat' = lat_acc - yawr spd" in header            # the fallback's kinematics, in the model's names


def test_the_step_reads_each_output_by_its_role(renamed):
    """The yaw rate is the model's first output here: the CasADi step and the numpy twin agree, and the
    lateral acceleration (the second entry of y) enters only its innovation, through the gains' a_y column."""
    config, b = renamed
    f = b.step_function()
    rng = np.random.default_rng(3)
    for _ in range(20):
        z = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.2, 0.2), 0.0, 0.0])
        u = np.array([rng.uniform(-1, 1), rng.uniform(-0.05, 0.05)])
        y = np.array([rng.uniform(-0.2, 0.2), rng.uniform(-3, 3)])      # (gyro, lat_acc)
        rho = np.array([rng.uniform(10, 35)])
        ref, excess = b.reference_step(z, u, y, rho)
        zc, ec = (np.array(v.full()).ravel() for v in f(z, u, y, rho))
        np.testing.assert_allclose(zc, ref, rtol=1e-9, atol=1e-12)
        assert float(ec[0]) == pytest.approx(excess, abs=1e-12)
    z, u, rho = np.zeros(4), np.zeros(2), np.array([20.0])
    base, _ = b.reference_step(z, u, np.zeros(2), rho)
    kicked, _ = b.reference_step(z, u, np.array([0.0, 0.01]), rho)          # lat_acc only
    np.testing.assert_allclose(kicked[:2] - base[:2], 0.01 * b.L[:, 0], rtol=1e-9)


class _Stepper:
    """The numpy twin of the step with the runtime's interface (names, ``run``): the excitation
    validation and the float32 comparison take their input rows by these names."""

    def __init__(self, b):
        self.b, self.input_names, self.output_names = b, tuple(b.input_names), tuple(b.output_names)

    def run(self, rows):
        rows = np.asarray(rows, float)
        nu, ny = self.b.nu, self.b.ny
        z, out, status = np.zeros(len(self.b.state_names)), [], []
        for row in rows:
            z, excess = self.b.reference_step(z, row[:nu], row[nu:nu + ny], row[nu + ny:])
            out.append(z[-2:])
            status.append(1 if excess > 0 else 0)
        return np.array(out), np.array(status), None


def test_the_excitation_validation_takes_the_models_names(renamed):
    """``uiogen validate --scenario excitation`` (and the float32 comparison, which records its input
    rows from that run) failed with "its inputs ['y_r'] are not signals of the model"."""
    from codegen.targets import float32
    from codegen.validation import excitation
    config, b = renamed
    result = excitation.run(config, duration=20.0, seed=1, observer=_Stepper(b))
    assert set(result["observer"]) == {"vlat", "yawr"}
    assert result["observer"]["yawr"]["rms_percent"] < 5.0, result["observer"]
    assert result["status_flags"] == 0
    assert set(float32.input_noise(config, b)) <= set(INPUTS)


def test_the_speed_box_is_read_under_the_models_name(tmp_path):
    path = project(tmp_path, params=PARAMS.replace("[scheduling.spd]", "[scheduling.v_x]"))
    with pytest.raises(SchedulingBoundsError, match=r"hatch\.toml: no \[scheduling\.spd\] table .*forward speed spd"
                                                    r".*\[scheduling\] has v_x, which the model does not schedule on"):
        FAMILY.build(observers.get(str(path)), FreshSolver())


@pytest.mark.parametrize("edit, message", [
    # the yaw rate measured in degrees: no output is a state itself
    (('("gyro", yawr)', '("gyro", 57.3 * yawr)'),
     r"tanh_car\.py: model 'tanh_hatchback': the yaw-rate role is open: no output is a state itself.*"
     r"MODEL\.outputs, declare one output as the yaw-rate state itself, e\.g\. \(\"yawr\", yawr\)"),
    # the states in the other order
    (("states=(vlat, yawr)", "states=(yawr, vlat)"),
     r"output 'gyro' measures the state yawr, the yaw rate.*declare states = \(vlat, yawr\) in MODEL"),
    # the longitudinal acceleration in a slip too: two candidates for the steering angle
    (("tr = (b * yawr - vlat) / spd", "tr = (b * yawr - vlat) / spd + 0.001 * ax_meas"),
     r"the steering-angle role is open: the known inputs \['ax_meas', 'steer'\] all enter the axle slips"),
])
def test_a_role_the_structure_leaves_open_is_refused_naming_it(tmp_path, capsys, edit, message):
    old, new = edit
    assert old in MODEL
    path = project(tmp_path, model=MODEL.replace(old, new))
    with pytest.raises(ModelDefinitionError, match=message):
        FAMILY.build(observers.get(str(path)), FreshSolver())
    assert cli.main(["design", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err and "ModelDefinitionError" in err, err


@pytest.mark.slow          # designs, emits and compiles the observer, double and float32
def test_every_verb_takes_the_models_names(tmp_path, capsys):
    """design, generate, build, validate --scenario excitation and build --float32 on the renamed
    model: the runtime's names and units are the model's, and neither the validation nor the float32
    comparison fails on names. The library's sensor noise is known by the built-in names (a_y, r), so
    this model declares its own (else the float32 tolerance is 0 and the build is refused on it, as for
    any model whose measured signals the library does not know); measured: accepted, bounds 6.1e-06
    m/s and 2.0e-06 rad/s against tolerances 1.1e-03 and 2.3e-04."""
    path = project(tmp_path, extra="\n[precision]\nnoise = { y_gyro = 0.005, y_lat_acc = 0.5 }\n")
    for argv in (["design", str(path), "--update"], ["generate", str(path)], ["build", str(path)]):
        assert cli.main(argv) == 0, argv
    from python_bindings import load
    obs = load(str(path))
    assert list(obs.input_names) == INPUTS and list(obs.output_names) == ["vlat", "yawr"]
    assert dict(zip(obs.input_names, obs.input_units)) == UNITS
    capsys.readouterr()
    assert cli.main(["validate", str(path), "--scenario", "excitation", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result["observer"]) == {"vlat", "yawr"}
    rc = cli.main(["build", str(path), "--float32"])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err and "not signals of the model" not in out + err
    assert rc == 0 and "obs: float32 accepted" in out and "OVER" not in out, out + err
    assert re.search(r"vlat +bound .* m/s +ok", out) and re.search(r"yawr +bound .* rad/s +ok", out), out
