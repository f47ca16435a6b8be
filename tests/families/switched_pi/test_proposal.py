"""Issue 42 item 1: the switched PI observer that ``uiogen analyze`` proposes for a model with two
measured scheduling signals (a car on a graded road: the gear ratio i_g and the speed v_x) reads
both, one axis of the speed rule (25) each, and its step takes both; where a proposal holds a
measured signal at a constant value (more signals than :data:`MAX_MODES` allows axes for), the
report, ``--json`` and the written observer file say so and the ranking puts it after the
proposals that read every signal. Before, the speed was frozen at mid-box (``[switching.fixed]
v_x = 22.5``), uncommented, the step never reading it."""
import json
import textwrap

import pytest

from codegen import analysis, cli
from codegen.analysis import ranking
from codegen.families.switched_pi import applicability
from codegen.families.switched_pi import design as switched_pi
from codegen.families.switched_pi import representation as switched

MODEL = '''
"""Longitudinal car on a graded road: engine speed and vehicle speed; gear ratio and speed measured."""
import sympy as sp
from codegen.model import ModelDefinition, SchedulingSignal

w_e, v = sp.symbols("w_e v")
T_e, theta = sp.symbols("T_e theta")
v_x = sp.Symbol("v_x", positive=True)
i_g = sp.Symbol("i_g", positive=True)
J_e, k_c, r_w, m, g, c_d = sp.symbols("J_e k_c r_w m g c_d", positive=True)

T_c = k_c * (w_e - i_g * v / r_w)          # the driveline's damped compliance
MODEL = ModelDefinition(
    name="grade_car",
    states=(w_e, v),
    known_inputs=(T_e,),
    unknown_inputs=(theta,),
    dynamics=sp.Matrix([(T_e - T_c) / J_e, i_g * T_c / (r_w * m) - g * theta - c_d * v_x * v / m]),
    outputs=(("w_e", w_e), ("v", v)),
    scheduling=(SchedulingSignal(i_g, "-"), SchedulingSignal(v_x, "m/s")),
    parameters=(J_e, k_c, r_w, m, g, c_d),
    units={"w_e": "rad/s", "v": "m/s", "T_e": "N m", "theta": "rad", "v_x": "m/s", "i_g": "-",
           "J_e": "kg m^2", "k_c": "N m s/rad", "r_w": "m", "m": "kg", "g": "m/s^2", "c_d": "kg/m"},
)
'''

PARAMETERS = '''
[parameters]
J_e = 0.2
k_c = 5.0
r_w = 0.3
m = 1400.0
g = 9.81
c_d = 0.4

[scheduling.i_g]
min = 3.0
max = 15.0
rate_min = -5.0
rate_max = 5.0

[scheduling.v_x]
min = 5.0
max = 40.0
rate_min = -4.0
rate_max = 4.0

[inputs]
T_e = { min = -50.0, max = 150.0, bandwidth = 1.0 }
theta = { min = -0.08, max = 0.08, bandwidth = 0.2 }
'''


@pytest.fixture
def car(tmp_path):
    (tmp_path / "model.py").write_text(textwrap.dedent(MODEL))
    (tmp_path / "parameters.toml").write_text(PARAMETERS)
    return tmp_path / "model.py", tmp_path / "parameters.toml"


def _entry(a, family="switched_pi"):
    return next((app, t) for app, t in a.ranking.entries if app.family == family)


def test_the_proposal_switches_on_every_measured_signal_and_its_step_reads_them(car):
    a = analysis.analyze(str(car[0]), str(car[1]), outputs=["v"])
    app, trial = _entry(a)
    rule = app.observer["switching"]
    assert [axis["premise"] for axis in rule["axis"]] == ["i_g", "v_x"] and "fixed" not in rule
    assert app.frozen == {} and "FROZEN" not in a.text()
    assert trial.status == "certified", trial.reason
    sm = switched.build(a.subject.model, a.subject.parameters, rule, "proposal")
    assert sm.n_modes == 9 and switched_pi.scheduling_inputs(sm) == ("i_g", "v_x")


@pytest.mark.slow       # two analyses with trial designs, about 15 s
def test_a_frozen_measured_signal_is_said_everywhere_and_ranked_after(car, tmp_path, monkeypatch, capsys):
    """More signals than axes (here MAX_MODES = 3: one axis): the speed is held at mid-box, and the
    report, the JSON, and the observer file ``uiogen new --from-model`` writes say so."""
    monkeypatch.setattr(applicability, "MAX_MODES", 3)
    a = analysis.analyze(str(car[0]), str(car[1]), outputs=["v"])
    app, trial = _entry(a)
    assert app.observer["switching"]["fixed"] == {"v_x": 22.5} and app.frozen == {"v_x": 22.5}
    text = a.text()
    assert "FROZEN measured signal: this proposal holds v_x = 22.5 (mid-box) and its observer does not read it" in text
    doc = json.loads(json.dumps(a.ranking.to_json(), default=str))
    entry = next(f for f in doc["families"] if f["family"] == "switched_pi")
    assert entry["frozen"] == {"v_x": 22.5} and "does not read it" in entry["frozen_means"]
    # every certified proposal that reads all the measured signals ranks before it
    k = a.ranking.position("switched_pi")
    assert all(not (t.status == "certified" and not o.frozen) for o, t in a.ranking.entries[k + 1:])
    written = ranking.starter_text(a.subject, app, tmp_path, trial=trial)
    assert "# WARNING: FROZEN measured signal: this proposal holds v_x = 22.5" in written
    assert "[switching.fixed]    # FROZEN: v_x held at mid-box" in written
    assert cli.main(["new", str(tmp_path / "proj"), "--from-model", str(car[0]), "--parameters", str(car[1]),
                     "--family", "switched_pi"]) == 0
    out = (tmp_path / "proj" / "grade_car_switched_pi.toml").read_text()
    assert "# WARNING: FROZEN" in out and "# FROZEN: v_x held at mid-box" in out


def test_a_frozen_proposal_ranks_after_one_that_reads_every_signal():
    """The ranking key: among certified proposals, one that holds a measured signal constant goes
    after one that reads them all, whatever the guarantee class."""
    points = ranking.Applicability("a", True, "attenuated_points")
    box = ranking.Applicability("b", True, "states_only", frozen={})
    frozen = ranking.Applicability("a", True, "attenuated_points", frozen={"v_x": 22.5})
    ok = ranking.Trial("a", "certified", "")
    assert ranking.sort_key(points, ok, 0) < ranking.sort_key(box, ok, 1)
    assert ranking.sort_key(frozen, ok, 0) > ranking.sort_key(box, ok, 1)


@pytest.mark.slow       # an analysis, a design, the C, a build and a run, about 25 s
def test_the_recommended_observer_of_the_grade_car_designs_and_estimates_the_grade(car, tmp_path, capsys):
    """Issue 42 item 1, through the user's path: ``uiogen new --from-model --outputs v`` writes the best-ranked
    observer over the user's model (a file that loads it and keeps the measured outputs), which designs,
    generates, builds and estimates the grade on the excitation run: measured 0.054 % RMS of the grade's (the
    algebraic UIO's exact decoupling; the switched PI proposal that froze the speed was 41 % off). Before,
    that file's design was refused: the user's model it loads was no part of the design's stamp."""
    import json

    from codegen.design import lock
    from codegen.project import observer_file as observers
    model, params = car
    assert cli.main(["new", str(tmp_path / "proj"), "--from-model", str(model), "--parameters", str(params),
                     "--outputs", "v"]) == 0
    (obs,) = (tmp_path / "proj").glob("*.toml")
    for argv in (["design", str(obs), "--update"], ["generate", str(obs)], ["build", str(obs)]):
        assert cli.main(argv) == 0, argv
    capsys.readouterr()
    assert cli.main(["validate", str(obs), "--scenario", "excitation", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["observer"]["theta"]["rms_percent"] < 1.0
    assert result["observer"]["v"]["rms_percent"] < 1.0
    # the user's model is in the design's stamp: an edit of it re-solves
    config = observers.get(str(obs))
    assert model.resolve() in lock.design_sources(config)
    before = lock.design_inputs(config)
    model.write_text(model.read_text() + "\n# edited\n")
    assert lock.design_inputs(observers.get(str(obs))) != before


@pytest.mark.slow       # an analysis and two designs, about 10 s
def test_a_model_that_loads_another_without_naming_it_is_refused_naming_the_fix(car, tmp_path, capsys):
    """The file ``new --from-model --outputs`` writes, with the user's model it loads no longer named as its
    BASE_MODEL (a path in a variable of another name): one typed line naming the file it read and the fix;
    named again, it designs."""
    model, params = car
    assert cli.main(["new", str(tmp_path / "proj"), "--from-model", str(model), "--parameters", str(params),
                     "--outputs", "v"]) == 0
    (obs,) = (tmp_path / "proj").glob("*.toml")
    (wrapper,) = (tmp_path / "proj").glob("*_model.py")
    text = wrapper.read_text()
    assert "BASE_MODEL = '../model.py'" in text and "observers.load_base(__file__, BASE_MODEL)" in text
    wrapper.write_text(text.replace("BASE_MODEL = '../model.py'", "_path = '../model.py'")
                       .replace("load_base(__file__, BASE_MODEL)", "load_base(__file__, _path)"))
    capsys.readouterr()
    assert cli.main(["design", str(obs), "--update"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert f"{wrapper}: the model imports the module {model.resolve()}" in err and 'BASE_MODEL = "PATH"' in err, err
    wrapper.write_text(text)
    assert cli.main(["design", str(obs), "--update"]) == 0
    # the project moved without the model it builds on: one line naming BASE_MODEL and the file (a process of
    # its own: this one holds the modules it loaded)
    import subprocess
    import sys
    model.rename(tmp_path / "elsewhere.py")
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "design", str(obs)], capture_output=True, text=True)
    err = proc.stderr.strip()
    assert proc.returncode == 2 and len(err.splitlines()) == 1, (proc.returncode, err)
    assert f"BASE_MODEL = '../model.py': there is no file {model.resolve()}" in err, err
