"""One model contract for every family (issue 23 items 2, 5, 6): a model file by path for every
family, the structures a family cannot take refused naming the family that can, every missing
setting in one error, ``uiogen new`` under a name that never shadows a built-in, and the model's
own equations as the plant of the excitation scenario and of campaigns for every family."""
import json
import re

import numpy as np
import pytest
import sympy as sp

from codegen import cli, families, pipeline
from codegen.certificate import gains
from codegen.errors import ConfigurationError, ModelDefinitionError
from codegen.model import load_parameters, parameter_substitution
from codegen.project import observer_file as observers

# A single-track model in (beta, r) with a measured speed state v: the scheduling speed v_x is
# derived from the measured output y_v; the unknown yaw moment Mz does not reach the outputs.
DERIVED_SPEED = '''
import sympy as sp
from codegen.model import ModelDefinition, SchedulingSignal
beta, r, v, delta, a_x, Mz = sp.symbols("beta r v delta a_x Mz")
v_x = sp.Symbol("v_x", positive=True)
M, I_z, l_f, l_r, C_f, C_r = sp.symbols("M I_z l_f l_r C_f C_r", positive=True)
F_yf = C_f * (delta - beta - l_f * r / v_x)
F_yr = C_r * (l_r * r / v_x - beta)
MODEL = ModelDefinition(
    name="sideslip_derived_speed", states=(beta, r, v), known_inputs=(delta, a_x), unknown_inputs=(Mz,),
    dynamics=sp.Matrix([(F_yf + F_yr) / (M * v_x) - r, (l_f * F_yf - l_r * F_yr + Mz) / I_z, a_x]),
    outputs=(("r", r), ("v", v)),
    scheduling=(SchedulingSignal(v_x, "m/s", derived=sp.Symbol("y_v")),),
    parameters=(M, I_z, l_f, l_r, C_f, C_r),
    units={"beta": "rad", "r": "rad/s", "v": "m/s", "delta": "rad", "a_x": "m/s^2", "Mz": "N m", "v_x": "m/s"})
'''

# The same car with the speed an input of its own, the lateral acceleration measured, and the
# disturbance a lateral force that reaches it (feedthrough).
FEEDTHROUGH = '''
import sympy as sp
from codegen.model import ModelDefinition, SchedulingSignal
beta, r, delta, F = sp.symbols("beta r delta F")
v_x = sp.Symbol("v_x", positive=True)
M, I_z, l_f, l_r, C_f, C_r = sp.symbols("M I_z l_f l_r C_f C_r", positive=True)
F_yf = C_f * (delta - beta - l_f * r / v_x)
F_yr = C_r * (l_r * r / v_x - beta)
MODEL = ModelDefinition(
    name="sideslip_disturbance", states=(beta, r), known_inputs=(delta,), unknown_inputs=(F,),
    dynamics=sp.Matrix([(F_yf + F_yr + F) / (M * v_x) - r, (l_f * F_yf - l_r * F_yr) / I_z]),
    outputs=(("r", r), ("a_y", (F_yf + F_yr + F) / M)),
    scheduling=(SchedulingSignal(v_x, "m/s"),),
    parameters=(M, I_z, l_f, l_r, C_f, C_r),
    units={"beta": "rad", "r": "rad/s", "delta": "rad", "F": "N", "a_y": "m/s^2", "v_x": "m/s"})
'''

PARAMS = """[parameters]
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
"""

INPUTS = """
[inputs]
delta = { min = -0.03, max = 0.03, bandwidth = 0.5 }
a_x = { min = -0.5, max = 0.5, bandwidth = 0.2 }
Mz = { min = -1500.0, max = 1500.0, bandwidth = 0.5 }
"""


def project(tmp_path, family, model=DERIVED_SPEED, params=PARAMS + INPUTS, extra=""):
    (tmp_path / "car.py").write_text(model)
    (tmp_path / "car.toml").write_text(params)
    obs = tmp_path / f"obs_{family}.toml"
    obs.write_text(f'family = "{family}"\nmodel = "car.py"\nparameters = "car.toml"\nsample_time = 0.01\n{extra}')
    return obs


# ---- uiogen new ------------------------------------------------------------------------------------------

def test_new_refuses_a_built_in_name_and_prints_paths(tmp_path, capsys):
    folder = tmp_path / "p"
    assert cli.main(["new", str(folder), "--family", "linf_uio", "--name", "lpv_linf_driver_torque"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "is a built-in observer" in err and "--name" in err, err
    assert not folder.exists()
    assert cli.main(["new", str(folder), "--family", "linf_uio", "--name", "2fast"]) == 2
    assert "C identifier" in capsys.readouterr().err
    assert cli.main(["new", str(folder), "--family", "linf_uio"]) == 0
    out = capsys.readouterr().out
    target = folder / "my_linf_uio.toml"               # the default name is never a built-in's
    assert target.is_file() and "my_linf_uio" not in observers.names()
    assert f"uiogen design {target} --update" in out and f"uiogen validate {target} --scenario excitation" in out
    head = target.read_text().split("family =")[0]
    assert f"uiogen generate {target}" in head and "lpv_linf_driver_torque" in head     # copied from, named
    assert 'model = "model.py"' in target.read_text() and 'parameters = "parameters.toml"' in target.read_text()


def test_new_prints_commands_that_paste_back_into_a_shell(tmp_path, capsys):
    """A folder with a space: every printed command splits (as a shell would) into the verb and the
    whole path, for --family and --from-model alike."""
    import shlex
    folder = tmp_path / "my car"
    assert cli.main(["new", str(folder), "--family", "switched_pi"]) == 0
    line = next(l for l in capsys.readouterr().out.splitlines() if l.startswith("next: "))
    for cmd in line[len("next: "):].split("; "):
        assert shlex.split(cmd)[2] == str(folder / "my_switched_pi.toml"), cmd
    other = tmp_path / "from model"
    assert cli.main(["new", str(other), "--from-model", str(folder / "model.py"), "--parameters",
                     str(folder / "parameters.toml")]) == 0
    line = next(l for l in capsys.readouterr().out.splitlines() if l.startswith("next: "))
    paths = {shlex.split(cmd)[2] for cmd in line[len("next: "):].split("; ")}
    assert len(paths) == 1 and paths.pop().startswith(str(other) + "/")


@pytest.mark.slow       # 4 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_the_design_hint_names_the_file(tmp_path, capsys):
    obs = project(tmp_path, "linf_uio", extra='polytope = "sector"\n')
    assert cli.main(["design", str(obs), "--update"]) == 0
    out = capsys.readouterr().out
    assert f"`uiogen generate {obs}` emits its C" in out, out[-400:]


# ---- the interconnected family loads its model by path ---------------------------------------------------

def test_interconnected_model_by_path_and_a_plain_model_refused(tmp_path):
    from codegen.families.interconnected_uio import representation as icm
    folder = tmp_path / "ic"
    assert cli.main(["new", str(folder), "--family", "interconnected_uio"]) == 0
    config = observers.get(str(folder / "my_interconnected_uio.toml"))
    ts = icm.load(config)                               # model.py beside the file, not model_defs/model.py.py
    assert [s.name for s in ts.subsystems] == ["longitudinal", "lateral"]
    one = config.load_model()                           # the same equations as one system
    assert one.state_names == tuple(map(str, ts.definition.states))
    assert [str(u) for u in one.known_inputs] == ["F_rr", "F_w"]      # exogenous: the plant's inputs
    plain = project(tmp_path, "interconnected_uio")
    with pytest.raises(ModelDefinitionError, match=r"InterconnectedModelDefinition.*linf_uio.*ts_fuzzy_uio"):
        pipeline.build(observers.get(str(plain)))


# ---- structures: what a family takes, and who takes what it refuses ---------------------------------------

def test_ts_takes_a_scheduling_speed_derived_from_a_measured_output(tmp_path):
    b = pipeline.build(observers.get(str(project(tmp_path, "ts_fuzzy_uio"))))
    assert b.input_names == ["delta", "a_x", "y_r", "y_v"]          # known inputs, then outputs: no speed input


@pytest.mark.parametrize("family, model, extra, message", [
    ("ts_fuzzy_uio", DERIVED_SPEED.replace('("v", v))', '("v", v), ("a_y", (F_yf + F_yr) / M))'), "",
     r"output 'a_y' = .* is not a state.*\(family linf_uio\) takes outputs"),
    ("switched_pi", FEEDTHROUGH, '[switching]\nperformance = ["beta"]\n[[switching.axis]]\nname = "v_x"\n'
     'premise = "v_x"\nunit = "m/s"\ncentres = [10.0, 25.0]\npoints = [{ v_x = 10.0 }, { v_x = 25.0 }]\n',
     # the advice it gives is one the family takes: y = C x, no input in an output (it said "needs y = C x + Du u"
     # and a probe's output that read the known steer was then refused for that)
     r"unknown inputs reach the outputs \(a_y <- F\).*needs y = C x, no input in an output .*\(family linf_uio\) "
     r"takes this feedthrough; or measure outputs that no input, known or unknown, reaches"),
    ("algebraic_uio", DERIVED_SPEED, "", r"derived scheduling signal\(s\) v_x.*\(family linf_uio\) and the TS fuzzy"),
    ("nonlinear_tyre_observer", DERIVED_SPEED, "[design]\nsigma_force_front = 1.0\nsigma_force_rear = 1.0\n",
     r"has 3 state\(s\).*needs two states \(the lateral speed, then the yaw rate\).*\(family linf_uio\)"),
    ("interconnected_uio", DERIVED_SPEED, "", r"InterconnectedModelDefinition.*other families take"),
])
def test_a_structure_a_family_cannot_take_names_the_family_that_can(tmp_path, capsys, family, model, extra, message):
    params = (PARAMS.replace("v = [5.0, 40.0]\n", "") + "\n[inputs]\ndelta = { min = -0.03, max = 0.03 }\n"
              "F = { min = -1.0, max = 1.0 }\n") if model == FEEDTHROUGH else PARAMS + INPUTS
    obs = project(tmp_path, family, model, params, extra)
    assert cli.main(["design", str(obs)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert re.search(message, err), err


def test_ts_refuses_a_scheduling_input_naming_the_family_that_takes_it(tmp_path):
    model = FEEDTHROUGH.replace('("a_y", (F_yf + F_yr + F) / M)', '("beta", beta)').replace("+ F) / (M * v_x)",
                                                                                             ") / (M * v_x) + F")
    obs = project(tmp_path, "ts_fuzzy_uio", model, PARAMS.replace("v = [5.0, 40.0]\n", "")
                  + "\n[inputs]\ndelta = { min = -0.03, max = 0.03 }\n")
    with pytest.raises(ModelDefinitionError, match=r"scheduling signal\(s\) v_x given as inputs.*linf_uio"):
        pipeline.build(observers.get(str(obs)))


# ---- every missing setting in one run -------------------------------------------------------------------

def test_excitation_names_every_missing_range_and_refuses_strays(tmp_path):
    from codegen.validation import excitation
    obs = project(tmp_path, "linf_uio", params=PARAMS, extra='polytope = "sector"\n')
    with pytest.raises(ModelDefinitionError, match=r"needs 3 table\(s\).*\[inputs.delta\].*\[inputs.a_x\].*"
                                                   r"\[inputs.Mz\]"):
        excitation.signal_functions(observers.get(str(obs)))
    # an input's [state_bounds] range is its range; a stray [inputs] key is refused with a did-you-mean
    (tmp_path / "car.toml").write_text(PARAMS.replace("v = [5.0, 40.0]", "v = [5.0, 40.0]\ndelta = [-0.02, 0.02]")
                                       + "\n[inputs]\na_x = { min = -0.5, max = 0.5 }\nMzz = { min = -1.0, max = 1.0 }\n")
    with pytest.raises(ConfigurationError, match=r"\[inputs\] Mzz = .*input or input scheduling signal.*did you mean 'Mz'"):
        excitation.signal_functions(observers.get(str(obs)))
    (tmp_path / "car.toml").write_text((tmp_path / "car.toml").read_text().replace("Mzz =", "Mz ="))
    t, funcs = excitation.signal_functions(observers.get(str(obs)))
    assert -0.02 <= funcs["delta"](t).min() < funcs["delta"](t).max() <= 0.02


def test_an_inputs_table_narrows_a_scheduling_sweep_inside_its_box(tmp_path):
    from codegen.validation import excitation
    obs = project(tmp_path, "linf_uio", model=FEEDTHROUGH, params=PARAMS.replace("v = [5.0, 40.0]\n", "")
                  + "\n[inputs]\ndelta = { min = -0.01, max = 0.01 }\nF = { min = 0.0, max = 0.0 }\n"
                  "v_x = { min = 10.0, max = 20.0 }\n", extra='polytope = "sector"\n')
    t, funcs = excitation.signal_functions(observers.get(str(obs)))
    assert 10.0 <= funcs["v_x"](t).min() < funcs["v_x"](t).max() <= 20.0
    assert np.all(funcs["F"](t) == 0.0)                  # min = max holds an input
    (tmp_path / "car.toml").write_text((tmp_path / "car.toml").read_text().replace("max = 20.0", "max = 50.0"))
    with pytest.raises(ConfigurationError, match=r"\[inputs.v_x\] min = 10.0: .*inside \[scheduling.v_x\]"):
        excitation.signal_functions(observers.get(str(obs)))


def test_algebraic_names_every_missing_differentiator(tmp_path):
    model = DERIVED_SPEED.replace('SchedulingSignal(v_x, "m/s", derived=sp.Symbol("y_v"))', 'SchedulingSignal(v_x, "m/s")')
    model = model.replace('outputs=(("r", r), ("v", v))', 'outputs=(("r", r),)').replace("states=(beta, r, v)",
                                                                                       "states=(beta, r)")
    model = model.replace(", a_x]),", "]),").replace("known_inputs=(delta, a_x)", "known_inputs=(delta,)")
    obs = project(tmp_path, "algebraic_uio", model, PARAMS.replace("v = [5.0, 40.0]\n", ""))
    with pytest.raises(ModelDefinitionError, match=r"2 differentiator setting\(s\) to fix: "
                                                   r"\[design.differentiators.y_r\] is missing .*order 1.*; "
                                                   r"\[design.differentiators.v_x\] is missing"):
        pipeline.build(observers.get(str(obs)))


# ---- the model's own equations as a plant ---------------------------------------------------------------

def _reference_run(model, params, sample_time, funcs, t, x0, substeps=10):
    """An independent numpy RK4 of the model's equations (sympy lambdify, derived signals from the outputs)."""
    subs = parameter_substitution(model, params)
    outputs = {sp.Symbol(f"y_{n}"): e for n, e in model.outputs}
    derived = {g.symbol: sp.sympify(g.derived).subs(outputs) for g in model.scheduling if g.derived is not None}
    raw = [g.symbol for g in model.scheduling if g.derived is None]
    ext = [*model.known_inputs, *model.unknown_inputs, *raw]
    args = [*model.states, *ext]
    f = sp.lambdify(args, sp.Matrix(model.dynamics).subs(derived).subs(subs), "numpy")
    h = sp.lambdify(args, sp.Matrix([e for _, e in model.outputs]).subs(subs), "numpy")
    hh = sample_time / substeps
    x = np.array(x0, float)
    X, Y = [], []
    for tk in t:
        e = lambda tt: [funcs[str(s)](np.array([tt]))[0] for s in ext]
        X.append(x.copy())
        Y.append(np.asarray(h(*x, *e(tk)), float).ravel())
        for j in range(substeps):
            t0 = tk + j * hh
            rhs = lambda z, tt: np.asarray(f(*z, *e(tt)), float).ravel()
            k1 = rhs(x, t0)
            k2 = rhs(x + 0.5 * hh * k1, t0 + 0.5 * hh)
            k3 = rhs(x + 0.5 * hh * k2, t0 + 0.5 * hh)
            k4 = rhs(x + hh * k3, t0 + hh)
            x = x + (hh / 6) * (k1 + 2 * k2 + 2 * k3 + k4)
    return np.array(X), np.array(Y)


def test_the_model_plant_is_an_rk4_of_the_models_own_equations(tmp_path):
    from codegen.validation import excitation
    config = observers.get(str(project(tmp_path, "linf_uio", extra='polytope = "sector"\n')))
    model, params = config.load_model(), load_parameters(config.parameter_path)
    truth = excitation.simulate(config, duration=3.0, seed=4)
    t, funcs = excitation.signal_functions(config, 3.0, 4)
    X, Y = _reference_run(model, params, config.sample_time, funcs, t, [0.0, 0.0, 22.5])
    for i, s in enumerate(model.state_names):
        assert np.max(np.abs(truth[s] - X[:, i])) <= 1e-12 * max(1.0, np.max(np.abs(X[:, i]))), s
    for j, (n, _) in enumerate(model.outputs):
        assert np.max(np.abs(truth[f"y_{n}"] - Y[:, j])) <= 1e-12 * max(1.0, np.max(np.abs(Y[:, j]))), n
    assert np.ptp(truth["v"]) > 0.1 and np.ptp(truth["Mz"]) > 100.0       # the run is excited


def test_the_compiled_campaign_plant_of_a_model_is_its_excitation_run():
    from codegen.campaign.plants import CompiledPlant
    from codegen.validation import excitation
    config = observers.get("algebraic_uio_example2")
    scn = excitation.scenario(config, 4.0, seed=3)
    out = CompiledPlant(config, scn.t.size, "model").simulate(scn)
    ref = excitation.simulate(config, 4.0, seed=3)
    for k in ("x1", "x2", "y_x1", "d", "rho"):
        scale = float(np.max(np.abs(ref[k])))
        assert np.max(np.abs(out[k] - ref[k])) <= 1e-12 * scale, k


def test_campaign_files_of_any_family_on_its_own_model(tmp_path):
    from codegen.campaign import spec as campaign_spec
    folder = tmp_path / "alg"
    assert cli.main(["new", str(folder), "--family", "algebraic_uio"]) == 0
    lock = folder / "generated_c" / "my_algebraic_uio"
    lock.mkdir(parents=True)
    (lock / "my_algebraic_uio_design.json").write_text(
        (observers.get("algebraic_uio_example2").workspace.design_lock("algebraic_uio_example2")).read_text())
    f = folder / "c.toml"

    def parse(text):
        f.write_text('observer = "my_algebraic_uio.toml"\nruns = 3\n' + text)
        return campaign_spec.load(f)
    spec = parse('scenarios = ["excitation"]\n')
    assert spec.observer == str((folder / "my_algebraic_uio.toml").resolve()) and spec.scenarios == ("excitation",)
    for text, message in [('scenarios = ["track_varying_speed"]\n', r'\["excitation"\]: observer .* of family '
                           r"'algebraic_uio', whose campaigns run on its own model"),
                          ('scenarios = ["excitation", "track_varying_speed"]\n', r"not both in one campaign"),
                          ('scenarios = ["excitation"]\n[driver]\nk_p = 1.0\n', r"the excitation scenario has no driver"),
                          ('scenarios = ["excitation"]\n[parameters]\nm = 1.0\n', r"must be a parameter of the plant")]:
        with pytest.raises(ConfigurationError, match=message):
            parse(text)


# ---- the rest of the verbs' generic paths ---------------------------------------------------------------

def test_check_gains_takes_a_design_lock_as_committed():
    config = observers.get("switched_pi_bank_angle")
    lock = json.loads(config.workspace.design_lock(config.name).read_text())
    assert "lmi_solutions" not in lock and "lmi_solutions" in lock["lock"]
    res = gains.check(families.get(config.family), config, lock, "lock")
    assert res.feasible and res.form == "lmi_solutions" and res.cases and res.certificate is not None


def test_the_shared_logs_peaks_are_the_logs_not_the_observers():
    from codegen.validation import logs, stanford
    assert stanford.peak_times("stanford") == stanford.PEAK_TIMES
    assert stanford.peak_times("/elsewhere/my_log.csv") == ()


@pytest.mark.slow       # runs the compiled step and the Kalman baselines over the shared log twice
def test_the_same_log_elsewhere_has_no_peaks_of_ours(tmp_path):
    from codegen.validation import logs, stanford
    here = logs.run("stanford_sideslip", "stanford")
    assert [round(p["t"]) for p in here["peaks"]] == [round(t) for t in stanford.PEAK_TIMES]
    copy = tmp_path / "my_log.csv.gz"
    copy.write_bytes(stanford._resolve("stanford").read_bytes())
    there = logs.run("stanford_sideslip", str(copy))
    assert there["peaks"] == [] and there["observer"] == here["observer"]


_FIELDS_MODEL = '''
import sympy as sp
from codegen.model import ModelDefinition, SchedulingSignal

v_y, r, delta, F = sp.symbols("v_y r delta F")
v_x = sp.Symbol("v_x", positive=True)
M, C_f = sp.symbols("M C_f", positive=True)
MODEL = ModelDefinition(
    name="fields", states=STATES, known_inputs=(delta,), unknown_inputs=(F,),
    dynamics=DYNAMICS, outputs=OUTPUTS, scheduling=SCHEDULING, parameters=PARAMETERS,
    units=UNITS)
'''
_FIELDS_OK = {"STATES": "(v_y, r)", "DYNAMICS": "sp.Matrix([C_f * (delta - v_y / v_x) / M + F / M - v_x * r, -3 * r])",
              "OUTPUTS": '(("r", r), ("v_y", v_y))', "SCHEDULING": '(SchedulingSignal(v_x, "m/s"),)',
              "PARAMETERS": "(M, C_f)", "UNITS": '{"v_y": "m/s", "r": "rad/s", "v_x": "m/s"}'}


@pytest.mark.parametrize("field, value, message", [
    ("OUTPUTS", '{"r": r, "v_y": v_y}', r"outputs must be a tuple of \(name, expression\) pairs"),
    ("OUTPUTS", "(r, v_y)", r"outputs must be a tuple of \(name, expression\) pairs"),
    ("PARAMETERS", '("M", C_f)', r"parameters must hold sympy symbols, got str 'M'; declare it with sp.symbols"),
    ("STATES", '("v_y", r)', r"states must hold sympy symbols, got str 'v_y'"),
    ("SCHEDULING", "(v_x,)", r"scheduling must hold SchedulingSignal\(symbol, unit\), got Symbol v_x; write "
                             r"SchedulingSignal\(v_x, \"UNIT\"\)"),
    ("DYNAMICS", "[-r, -r]", r"dynamics must be a sympy Matrix, one row per state .*got list"),
    ("UNITS", '{"vy": "m/s", "r": "rad/s"}', r"units\['vy'\] names no signal .*did you mean 'v_y'\? it has no unit"),
])
def test_a_model_field_of_the_wrong_type_is_one_line_naming_the_file_and_field(tmp_path, capsys, field, value,
                                                                                 message):
    """A field of the wrong type was whatever Python raised first: 'ValueError: not enough values
    to unpack' for outputs as a dict, an AttributeError traceback ('str' object has no attribute
    'is_positive') for a parameter given as a string; a misspelt units key was ignored. Each is now
    a ModelDefinitionError naming the model file and the field, exit code 2."""
    text = _FIELDS_MODEL
    for k, v in {**_FIELDS_OK, field: value}.items():
        text = text.replace(k, v, 1) if k != "UNITS" else text.replace("units=UNITS", f"units={v}")
    (tmp_path / "m.py").write_text(text)
    (tmp_path / "car.toml").write_text("[parameters]\nM = 1500.0\nC_f = 1e5\n\n[scheduling.v_x]\nmin = 5.0\n"
                                       "max = 30.0\nrate_min = -1.0\nrate_max = 1.0\n")
    rc = cli.main(["analyze", str(tmp_path / "m.py"), "--parameters", str(tmp_path / "car.toml"), "--no-design"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "Traceback" not in err
    assert f"ModelDefinitionError: {tmp_path / 'm.py'}: model 'fields': " in err
    assert re.search(message, err), err


def test_a_model_with_every_field_right_loads(tmp_path, capsys):
    text = _FIELDS_MODEL
    for k, v in _FIELDS_OK.items():
        text = text.replace(k, v, 1) if k != "UNITS" else text.replace("units=UNITS", f"units={v}")
    (tmp_path / "m.py").write_text(text)
    (tmp_path / "car.toml").write_text("[parameters]\nM = 1500.0\nC_f = 1e5\n\n[scheduling.v_x]\nmin = 5.0\n"
                                       "max = 30.0\nrate_min = -1.0\nrate_max = 1.0\n")
    assert cli.main(["analyze", str(tmp_path / "m.py"), "--parameters", str(tmp_path / "car.toml"),
                     "--no-design"]) == 0
