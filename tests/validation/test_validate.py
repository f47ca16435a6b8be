"""`uiogen validate`: both plants, the baselines in the same run, JSON and plot outputs."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from codegen.validation import run as validate
from codegen.errors import ModelDefinitionError

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())


@pytest.mark.slow          # the compiled observer
def test_nominal_plant_short_run(fresh_cache):
    # progress is reported while the plant runs: a run kept from another test would not run it
    ticks = []
    r = validate.run_scenario("lpv_linf_driver_torque", "zigzag_constant_speed_assist", "nominal", duration=8.0,
                              progress=ticks.append)
    assert r["status_flags"] == 0 and r["samples"] == 801
    assert ticks[-1] == 1.0 and len(ticks) > 10 and ticks == sorted(ticks)
    assert r["plant_model"] == "steering_single_track_pacejka_plant"
    # one definition: every figure in the row's unit (a plane angle in deg, converted from the declared
    # rad and marked so; rates as declared), the truth's RMS and the error in % of it, NMSE % of eq. (32)
    obs = r["observer"]
    assert set(obs) == {"beta", "r", "delta", "delta_dot", "T_d"}
    assert obs["beta"]["unit"] == "deg" and obs["beta"]["converted_from"] == "rad"
    assert obs["r"]["unit"] == "rad/s" and "converted_from" not in obs["r"]
    assert obs["T_d"]["unit"] == "N m" and obs["T_d"]["after_s"] == 2.0
    for row in obs.values():
        assert row["rms_percent"] == pytest.approx(100 * row["rms"] / row["truth_rms"])
        assert "rmse_percent" not in row
    assert 0 < obs["beta"]["nmse_percent"] <= 100
    # the paper's Table II format beside it: E_mean, E_max, Std, RMS, rates in deg/s
    table2 = r["paper_format"]["rows"]
    assert table2["r"]["unit"] == "deg/s" and table2["r"]["RMS"] == pytest.approx(np.degrees(obs["r"]["rms"]))
    assert table2["beta"]["E_mean"] == obs["beta"]["mae"] and "beta linear_kf" in table2
    # exact-model plant at 15 m/s: the observer must track sideslip closely
    assert obs["beta"]["rms"] < 0.1 and table2["r"]["RMS"] < 0.1
    assert set(r["baselines"]) == {"linear_kf", "ekf"}
    assert all(np.isfinite(v["beta"]["rms"]) for v in r["baselines"].values())


@pytest.mark.slow          # the compiled observer
def test_commonroad_requires_a_twin_designed_for_that_car():
    pytest.importorskip("vehiclemodels")
    with pytest.raises(ModelDefinitionError, match="lpv_linf_driver_torque_bmw320i"):
        validate.run_scenario("lpv_linf_driver_torque", "circular_path", "commonroad", duration=3.0)


@pytest.mark.slow          # the compiled observer
def test_commonroad_cli_json_and_plot(tmp_path):
    pytest.importorskip("vehiclemodels")
    png = tmp_path / "v.png"
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "validate", "lpv_linf_driver_torque_bmw320i",
                           "--scenario", "circular_path", "--plant", "commonroad", "--duration", "6",
                           "--json", "--plot", str(png)], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert set(res) >= {"observer", "baselines"}
    for sig in ("beta", "T_d"):
        assert set(res["observer"][sig]) >= {"unit", "rms", "truth_rms", "rms_percent", "mae", "max", "nmse_percent"}
    assert res["observer"]["beta"]["unit"] == "deg" and res["observer"]["T_d"]["unit"] == "N m"
    assert "truth_rms" in res["definitions"] and "paper_format" in res
    # 6 s of the circle (a_y up to 4.7 m/s^2): 0.009 deg and 0.28 N m with the camber/remainder
    # model; the paper's linear model gave 0.088 deg and 1.45 N m
    assert res["observer"]["beta"]["rms"] < 0.03
    assert res["observer"]["T_d"]["rms"] < 0.5
    assert png.stat().st_size > 10_000


def test_committed_commonroad_parameters_are_derived_not_typed():
    pytest.importorskip("vehiclemodels")
    from codegen.validation import commonroad_plant
    text = (ROOT / "model_defs" / "params" / "commonroad_bmw320i.toml").read_text()
    assert text == commonroad_plant.params_toml(2)


class _ZeroObserver:
    """A stand-in compiled step: reads the model's outputs, estimates zero."""
    input_names = ("dw", "y_r", "y_ay", "y_p")
    output_names = ("phir",)

    def run(self, inputs):
        n = len(inputs)
        return np.zeros((n, 1)), np.zeros(n, dtype=int), None


@pytest.mark.parametrize("output_name", ["ay", "a_y"])
def test_excitation_reports_max_abs_ay_only_for_an_output_named_a_y(tmp_path, monkeypatch, output_name):
    """A model whose lateral acceleration is not an output named a_y (a user's roll model names it
    ``ay``): the JSON's max_abs_ay is null and the header has no ``max |a_y|`` (it printed 0.00, a
    made-up figure, for any such model); with the output named a_y, its peak."""
    from codegen import pipeline
    from codegen.project import observer_file as observers
    from codegen.validation import excitation
    case = ROOT / "tests" / "analysis" / "models" / "roll_bank"
    model = (case / "roll.py").read_text()
    if output_name != "ay":
        # the output and its unit renamed together (a units key left behind is refused as misspelt)
        model = model.replace('("ay", ay)', f'("{output_name}", ay)').replace('"ay": ', f'"{output_name}": ')
    (tmp_path / "roll.py").write_text(model)
    (tmp_path / "roll_params.toml").write_text((case / "roll_params.toml").read_text())
    (tmp_path / "obs.toml").write_text('family = "linf_uio"\nmodel = "roll.py"\nparameters = "roll_params.toml"\n'
                                       'sample_time = 0.01\npolytope = "sector"\n')
    config = observers.get(str(tmp_path / "obs.toml"))

    class Build:
        def output_lags(self):
            return {}

    monkeypatch.setattr(pipeline, "build", lambda config: Build())
    obs = _ZeroObserver()
    obs.input_names = tuple(n.replace("y_ay", f"y_{output_name}") for n in obs.input_names)
    r = {"family": "linf_uio", **excitation.run(config, 3.0, observer=obs)}
    head = validate.header("roll", r)
    data = json.loads(validate.to_json(r))
    if output_name == "ay":
        assert r["max_abs_ay"] is None and data["max_abs_ay"] is None and "a_y" not in head, head
    else:
        assert r["max_abs_ay"] > 0.01 and data["max_abs_ay"] == r["max_abs_ay"]
        assert f"max |a_y| {r['max_abs_ay']:.2f} m/s^2" in head
    assert "max_abs_ay" in data["definitions"]


@pytest.mark.parametrize("entries, message", [
    # a misspelt input: named, with the input it meant (it said 'y_gyro = None ... missing: y_gyro')
    ({"y_gyr": "gyro_dps", "y_ay": "ay", "y_p": "p", "dw": "dw"},
     r"obs.toml: \[data.inputs\] y_gyr = \{column = \"gyro_dps\", unit = \"deg/s\"\}: not an input of observer obs: "
     r"one of dw, y_r, y_ay, y_p; missing: y_r \(did you mean 'y_r'\?\)"),
    ({"y_r": "gyro_dps", "y_ay": "ay", "dw": "dw"},
     r"obs.toml: \[data.inputs\] y_p is missing: a column for every observer input \(dw, y_r, y_ay, y_p\); missing: y_p$"),
])
def test_a_misspelt_data_input_is_named_with_a_did_you_mean(tmp_path, monkeypatch, capsys, entries, message):
    import re
    from codegen import cli
    from codegen.extension import build as extension
    case = ROOT / "tests" / "analysis" / "models" / "roll_bank"
    for f in ("roll.py", "roll_params.toml"):
        (tmp_path / f).write_text((case / f).read_text())
    rows = "".join(f'{k} = {{ column = "{c}", unit = "{"deg/s" if c == "gyro_dps" else "1"}" }}\n'
                   for k, c in entries.items())
    (tmp_path / "obs.toml").write_text('family = "linf_uio"\nmodel = "roll.py"\nparameters = "roll_params.toml"\n'
                                       'sample_time = 0.01\npolytope = "sector"\n\n[data]\ntime = "t"\n\n'
                                       f'[data.inputs]\n{rows}')
    obs = _ZeroObserver()
    obs.input_names = ("dw", "y_r", "y_ay", "y_p")
    monkeypatch.setattr(extension, "load", lambda config: obs)
    monkeypatch.setattr(extension, "require_current", lambda config: None)
    (tmp_path / "log.csv").write_text("t,gyro_dps,ay,p,dw\n0,0,0,0,0\n")
    assert cli.main(["validate", str(tmp_path / "obs.toml"), "--data", str(tmp_path / "log.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert re.search(message, err), err


def _roll_project(tmp_path, edit=lambda text: text):
    from codegen.project import observer_file as observers
    case = ROOT / "tests" / "analysis" / "models" / "roll_bank"
    (tmp_path / "roll.py").write_text(edit((case / "roll.py").read_text()))
    (tmp_path / "roll_params.toml").write_text((case / "roll_params.toml").read_text())
    (tmp_path / "obs.toml").write_text('family = "linf_uio"\nmodel = "roll.py"\nparameters = "roll_params.toml"\n'
                                       'sample_time = 0.01\npolytope = "sector"\n')
    return observers.get(str(tmp_path / "obs.toml"))


def test_an_unstable_plant_is_refused_not_tabulated(tmp_path):
    """A model that is an unstable plant (here the roll stiffness with the wrong sign: phi grows as
    e^{12 t} to 1e100 and beyond while staying finite) gave a table with a truth RMS of 1e100, no
    warning and a 200-digit NMSE; now the run is refused naming the state, the range it left and when."""
    from codegen.validation import excitation
    config = _roll_project(tmp_path, lambda text: text.replace("- Kphi * phi", "+ Kphi * phi"))
    with pytest.raises(ModelDefinitionError, match=r"the plant diverged in the excitation run: state phi left "
                       r"10 x the plausible range of an angle \(\+-12\.57 rad\) at t = [0-9.]+ s and reached "
                       r"\|phi\| = [0-9.]+e\+[0-9]+ rad.*would measure the divergence.*roll_params\.toml"):
        excitation.simulate(config, 30.0)
    # the stable model runs as before
    (tmp_path / "stable").mkdir()
    assert np.abs(excitation.simulate(_roll_project(tmp_path / "stable"), 5.0)["phi"]).max() < 1.0


def test_the_figures_table_stays_readable_for_huge_figures():
    """NMSE was printed with .2f: a 200-digit number; every figure is now 4 significant digits."""
    from codegen.validation.common import format_stats
    from codegen.validation.metrics import signal_report
    est = np.array([0.0, 0.0, 0.0, 1e100])           # an estimate far off: NMSE -2e201 %
    text = format_stats({"phi": signal_report(np.array([1.0, 2.0, 3.0, 4.0]), est, unit="m"), "ok": signal_report(
        np.array([1.0, 2.0, 3.0]), np.array([1.1, 2.0, 2.9]), unit="m")})
    assert max(len(line) for line in text.splitlines()) < 110, text
    assert "-2e+201" in text and all(len(cell) <= 10 for cell in text.split()), text
    assert " 99" in text.splitlines()[2] or "98.5" in text, text


class _EchoObserver:
    """A stand-in compiled step whose estimate of phir is its input dw (a perfect estimate when the
    log's reference column is dw in the declared unit)."""
    input_names = ("dw", "y_r", "y_ay", "y_p")
    output_names = ("phir",)
    sample_time = 0.01

    def initial_state(self):
        return None

    def run(self, inputs, state=None):
        n = len(inputs)
        return np.asarray(inputs)[:, :1].copy(), np.zeros(n, dtype=int), state


@pytest.mark.parametrize("unit, message", [
    ("rad", None),
    # logged in rad, declared deg: RMS % 5620 and NMSE -319613 with no warning (the small-range warning
    # needs a factor of 100)
    ("deg", r"log.csv: \[data.truth\] phir: column 'ref' \(reference of phir, declared deg\): the estimate's RMS is "
            r"57.3 x the reference's after the first 2 s, so the RMS % and NMSE of phir measure that factor, not the "
            r"observer's error; the column looks like rad \(x 57.3\), not deg: declare unit = \"rad\" for 'ref' in "
            r"\[data.truth\] if that is its unit"),
    # logged in rad, declared mrad: the small-range warning names it (once)
    ("mrad", r"declared mrad\) spans .* under 1/100 of the model's box .* in rad \(x 1000\)"),
])
def test_a_reference_column_in_another_unit_is_named(tmp_path, monkeypatch, capsys, unit, message):
    import re
    from codegen import cli
    from codegen.extension import build as extension
    case = ROOT / "tests" / "analysis" / "models" / "roll_bank"
    for f in ("roll.py", "roll_params.toml"):
        (tmp_path / f).write_text((case / f).read_text())
    (tmp_path / "obs.toml").write_text(
        'family = "linf_uio"\nmodel = "roll.py"\nparameters = "roll_params.toml"\nsample_time = 0.01\n'
        'polytope = "sector"\n\n[data]\ntime = "t"\n\n[data.inputs]\n'
        + "".join(f'{k} = {{ column = "{k}", unit = "{u}" }}\n'
                  for k, u in (("dw", "rad"), ("y_r", "rad/s"), ("y_ay", "m/s^2"), ("y_p", "rad/s")))
        + f'\n[data.truth]\nphir = {{ column = "ref", unit = "{unit}" }}\n')
    monkeypatch.setattr(extension, "load", lambda config: _EchoObserver())
    monkeypatch.setattr(extension, "require_current", lambda config: None)
    t = np.arange(0, 20, 0.01)
    dw = 0.02 * np.sin(0.7 * t) + 0.01 * np.sin(2.3 * t)
    with open(tmp_path / "log.csv", "w") as fh:
        fh.write("t,dw,y_r,y_ay,y_p,ref\n")
        for row in zip(t, dw, dw * 0, dw * 0, dw * 0, dw):
            fh.write(",".join(repr(float(v)) for v in row) + "\n")
    assert cli.main(["validate", str(tmp_path / "obs.toml"), "--data", str(tmp_path / "log.csv"), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    if message is None:
        assert res["warnings"] == [] and res["observer"]["phir"]["rms"] < 1e-12
        return
    assert len(res["warnings"]) == 1 and re.search(message, res["warnings"][0]), res["warnings"]
    assert cli.main(["validate", str(tmp_path / "obs.toml"), "--data", str(tmp_path / "log.csv")]) == 0
    out = capsys.readouterr().out
    assert re.search("warning: .*" + message, out), out


def test_columns_no_physics_check_reads_are_listed(tmp_path, monkeypatch, capsys):
    """The roll rate y_p of the roll model is read by no relation of the model (the one judged relation,
    a_y from the yaw dynamics, reads dw, y_r, y_ay, vx): a y_p column in rad/s declared deg/s passed
    without a word. validate now lists it (text and JSON), and only it."""
    from codegen import cli
    from codegen.extension import build as extension
    from codegen.validation import excitation
    case = ROOT / "tests" / "analysis" / "models" / "roll_bank"
    for f in ("roll.py", "roll_params.toml"):
        (tmp_path / f).write_text((case / f).read_text())
    units = {"dw": "rad", "y_r": "rad/s", "y_ay": "m/s^2", "y_p": "deg/s", "vx": "m/s"}
    (tmp_path / "obs.toml").write_text(
        'family = "linf_uio"\nmodel = "roll.py"\nparameters = "roll_params.toml"\nsample_time = 0.01\n'
        'polytope = "sector"\n\n[data]\ntime = "t"\n\n[data.inputs]\n'
        + "".join(f'{k} = {{ column = "{k}_col", unit = "{u}" }}\n' for k, u in units.items()))
    from codegen.project import observer_file as observers
    run = excitation.simulate(observers.get(str(tmp_path / "obs.toml")), 20.0)
    obs = _EchoObserver()
    obs.input_names = tuple(units)
    monkeypatch.setattr(extension, "load", lambda config: obs)
    monkeypatch.setattr(extension, "require_current", lambda config: None)
    with open(tmp_path / "log.csv", "w") as fh:
        fh.write("t," + ",".join(f"{k}_col" for k in units) + "\n")
        for row in zip(run["t"], *(run[k] for k in units)):          # y_p logged in rad/s
            fh.write(",".join(repr(float(v)) for v in row) + "\n")
    args = ["validate", str(tmp_path / "obs.toml"), "--data", str(tmp_path / "log.csv")]
    assert cli.main([*args, "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["warnings"] == []
    assert res["unchecked_columns"] == [{"signal": "y_p", "column": "y_p_col", "unit": "deg/s", "table": "data.inputs",
                                         "why": "no physics relation of the model reads it", "range_checked": False}]
    assert cli.main(args) == 0
    out = capsys.readouterr().out
    assert ("unchecked: 'y_p_col' ([data.inputs] y_p, unit deg/s: no physics relation of the model reads it; no range "
            "either). No physics check covered it (a range check, where there is one, misses a unit off by a factor "
            "under 100 inside the model's box): double-check its unit") in out, out


@pytest.mark.slow          # the compiled observer
def test_a_run_whose_step_failed_numerically_is_a_failed_validation(monkeypatch, capsys):
    """The excitation run counts each status bit; a step that reported NUMERICAL_FAILURE (it reset its
    state) or an estimate that diverged makes `uiogen validate` exit 1 with the reason on stderr (a
    user's TS observer started outside its box diverged to 1e269 and validate exited 0)."""
    from codegen import cli
    good = validate.run_scenario("lpv_linf_driver_torque", "excitation", duration=6.0)
    assert "NUMERICAL_FAILURE" not in good["status_counts"] and validate.failure(good) == ""
    bad = {**good, "status_counts": {**good["status_counts"], "NUMERICAL_FAILURE": 3},
           "observer": {**good["observer"], "T_d": {**good["observer"]["T_d"], "rms": float("inf")}}}
    assert validate.failure(bad) == (f"the step reported NUMERICAL_FAILURE on 3 of {good['samples']} samples and "
                                     f"reset its state there; the error of T_d is not finite (the estimate diverged)")
    monkeypatch.setattr(validate, "run_scenario", lambda *a, **k: bad)
    assert cli.main(["validate", "lpv_linf_driver_torque", "--scenario", "excitation", "--json"]) == 1
    out = capsys.readouterr()
    assert json.loads(out.out)["status_counts"]["NUMERICAL_FAILURE"] == 3
    assert out.err.startswith("uiogen: validation failed: the step reported NUMERICAL_FAILURE on 3 of")
    monkeypatch.setattr(validate, "run_scenario", lambda *a, **k: good)
    assert cli.main(["validate", "lpv_linf_driver_torque", "--scenario", "excitation"]) == 0
