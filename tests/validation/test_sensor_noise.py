"""Sensor noise (issue 42 item 2): declared once, in the parameter file's ``[sensor_noise]``; the
excitation scenario adds it by default (``--noise-free`` without, and a run with none declared says
so); every estimate that carries no information (error RMS >= its truth's RMS about its mean) is
named, in the text, the JSON and with ``--fail-uninformative`` the exit code."""
import json
from pathlib import Path

import numpy as np
import pytest

from codegen import cli
from codegen.errors import ConfigurationError, UnitError
from codegen.model import load_parameters
from codegen.validation import noise, run as validate

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
CASE = ROOT / "tests" / "analysis" / "models" / "roll_bank"


class _EchoObserver:
    """A stand-in compiled step of the roll model: it reads the measured signals and estimates the bank
    angle phir as zero (no estimate of it at all)."""
    input_names = ("dw", "y_r", "y_ay", "y_p", "vx")
    output_names = ("phir",)

    def run(self, inputs):
        n = len(inputs)
        return np.zeros((n, 1)), np.zeros(n, dtype=int), None


def _project(tmp_path, table: str = ""):
    """The roll model with ``table`` appended to its parameter file, under the first family's example
    observer file (any family: the step is a stand-in)."""
    import re
    from codegen import families
    from codegen.project import observer_file as observers
    (tmp_path / "roll.py").write_text((CASE / "roll.py").read_text())
    (tmp_path / "roll_params.toml").write_text((CASE / "roll_params.toml").read_text() + table)
    family = next(families.get(f) for f in families.names() if families.get(f).example)
    text = Path(observers.get(family.example).source).read_text()
    text = re.sub(r'^model = "[^"]*"', 'model = "roll.py"', text, count=1, flags=re.M)
    text = re.sub(r'^parameters = "[^"]*"', 'parameters = "roll_params.toml"', text, count=1, flags=re.M)
    (tmp_path / "obs.toml").write_text(text)
    return observers.get(str(tmp_path / "obs.toml"))


def _run(config, monkeypatch, **kw):
    from codegen import pipeline
    from codegen.validation import excitation

    class Build:
        def output_lags(self):
            return {}
    monkeypatch.setattr(pipeline, "build", lambda config: Build())
    return {"family": config.family, **excitation.run(config, 6.0, observer=_EchoObserver(), **kw)}


TABLE = '\n[sensor_noise]\nr = { std = 0.5, unit = "deg/s" }\nay = 0.05\nvx = { std = 0.36, unit = "km/h" }\n'


def test_the_excitation_run_adds_the_declared_noise_by_default(tmp_path, monkeypatch):
    """The declared levels reach what the observer reads (in the model's unit: deg/s and km/h converted),
    seeded (the same run twice, the same draws), said in the header line and the JSON; --noise-free reads
    the truth itself; a file without the table runs noise free and says so."""
    config = _project(tmp_path, TABLE)
    res = _run(config, monkeypatch)
    rec = res["noise"]
    assert rec["mode"] == "declared" and rec["source"].endswith("roll_params.toml")
    assert rec["levels"] == pytest.approx({"y_r": np.deg2rad(0.5), "y_ay": 0.05, "vx": 0.1}, rel=1e-12)
    assert rec["noise_free"] == ["dw", "y_p"]
    truth, measured = res["signals"]["truth"], res["signals"]["measured"]
    for col, std in rec["levels"].items():
        got = np.std(measured[col] - truth[col])
        assert got == pytest.approx(std, rel=0.05), col
    assert np.array_equal(measured["y_p"], truth["y_p"]) and np.array_equal(measured["dw"], truth["dw"])
    again = _run(config, monkeypatch)
    assert all(np.array_equal(again["signals"]["measured"][c], measured[c]) for c in measured)
    table = validate.format_table(res)
    assert table.splitlines()[0] == (f"sensor noise (std, seeded white, seed 0, [sensor_noise] of {rec['source']}): "
                                     f"y_r 0.00873 rad/s, y_ay 0.05 m/s^2, vx 0.1 m/s; noise free: dw, y_p")
    assert json.loads(validate.to_json(res))["noise"]["levels"]["y_ay"] == 0.05

    off = _run(config, monkeypatch, noise=False)
    assert off["noise"]["mode"] == "off" and off["noise"]["levels"] == {}
    assert all(np.array_equal(off["signals"]["measured"][c], truth[c]) for c in measured)
    assert validate.format_table(off).startswith("sensor noise: none (--noise-free)")

    (tmp_path / "none").mkdir()
    quiet = _run(_project(tmp_path / "none"), monkeypatch)
    assert quiet["noise"]["mode"] == "none declared"
    assert validate.format_table(quiet).startswith("sensor noise: none declared (")
    assert "a noise-free run" in validate.format_table(quiet).splitlines()[0]


def test_an_estimate_without_information_is_named(tmp_path, monkeypatch, capsys):
    """An estimate no better than a constant (here zero for the bank angle) is named with its figures in
    the text and the JSON (``no_information``, ``uninformative``); --fail-uninformative exits 3."""
    res = _run(_project(tmp_path, TABLE), monkeypatch)
    row = res["observer"]["phir"]
    assert row["no_information"] is True and row["rms"] >= row["truth_std"] > 0
    assert noise.uninformative(res["observer"]) == {"phir": row}
    monkeypatch.setattr(validate, "run_scenario", lambda *a, **k: res)
    assert cli.main(["validate", str(tmp_path / "obs.toml"), "--scenario", "excitation"]) == 0
    out = capsys.readouterr()
    line = (f"no information: phir (error RMS {row['rms']:.4g} >= {row['truth_std']:.4g} deg, its truth's RMS "
            f"about its mean; NMSE {row['nmse_percent']:.4g} %): the truth's mean (a constant) would estimate it as "
            f"well; below the noise floor of the declared sensor noise")
    assert line in out.out.splitlines() and out.err == f"uiogen: warning: {line}\n"
    assert cli.main(["validate", str(tmp_path / "obs.toml"), "--scenario", "excitation", "--json",
                     "--fail-uninformative"]) == 3
    out = capsys.readouterr()
    data = json.loads(out.out)
    assert data["uninformative"] == ["phir"] and data["observer"]["phir"]["no_information"] is True
    assert "no_information" in data["definitions"] and "truth_std" in data["definitions"]
    assert "--fail-uninformative" in out.err
    # an informative estimate: nothing said, exit 0 even with --fail-uninformative
    good = {**res, "observer": {"phir": {**row, "rms": 0.1 * row["truth_std"], "no_information": False}}}
    monkeypatch.setattr(validate, "run_scenario", lambda *a, **k: good)
    assert cli.main(["validate", str(tmp_path / "obs.toml"), "--scenario", "excitation", "--fail-uninformative"]) == 0
    out = capsys.readouterr()
    assert "no information" not in out.out and out.err == ""


@pytest.mark.parametrize("entry, error, message", [
    ("y_r = 0.001", ConfigurationError,
     r"roll_params.toml: \[sensor_noise\] y_r = 0.001: not a measured signal of model 'roll_bank'; its measured "
     r"signals: r \(output\), ay \(output\), p \(output\), dw \(known input\), vx \(scheduling signal\) "
     r"\(did you mean 'r'\?\)"),
    ("a_y = 0.05", ConfigurationError, r"\[sensor_noise\] a_y = 0.05: not a measured signal .* \(did you mean 'ay'\?\)"),
    ("phi = 0.01", ConfigurationError, r"\[sensor_noise\] phi = 0.01: not a measured signal"),   # a state, not measured
    ("r = -0.001", ConfigurationError, r"roll_params.toml: \[sensor_noise\] r = -0.001: must be a standard deviation "
                                       r">= 0 in the signal's unit"),
    ('r = "0.05 deg/s"', ConfigurationError, r"\[sensor_noise\] r = \"0.05 deg/s\": must be a standard deviation"),
    ("r = { std = -1.0 }", ConfigurationError, r"\[sensor_noise.r\] std = -1.0: must be a finite number >= 0"),
    ("r = { sd = 0.05, unit = \"deg/s\" }", ConfigurationError, r"\[sensor_noise.r\] .*did you mean 'std'"),
    ('r = { std = 0.05, unit = "m/s^2" }', UnitError,
     r"roll_params.toml: \[sensor_noise.r\] unit = 'm/s\^2': not a unit of r, which the model declares in 'rad/s'"),
    ('r = { std = 0.05, unit = "furlong" }', UnitError, r"\[sensor_noise.r\] unit = 'furlong': unit 'furlong'"),
])
def test_a_bad_noise_table_is_one_typed_line(tmp_path, entry, error, message):
    config = _project(tmp_path, f"\n[sensor_noise]\n{entry}\n")
    with pytest.raises(error, match=message):
        noise.declared(config.load_model(), load_parameters(config.parameter_path))


def test_a_table_of_the_right_names_and_units_is_read_in_the_model_units(tmp_path):
    config = _project(tmp_path, TABLE + 'p = { std = 0.1, unit = "rad/s" }\ndw = 0.0\n')
    got = noise.declared(config.load_model(), load_parameters(config.parameter_path))
    assert got == pytest.approx({"r": np.deg2rad(0.5), "ay": 0.05, "vx": 0.1, "p": 0.1, "dw": 0.0}, rel=1e-12)


def test_the_table_is_no_design_input(tmp_path):
    """Declaring or editing the sensors' noise re-solves nothing: the parameter file's design hash
    leaves [sensor_noise] out (so a starter's copy with the table replays the example's design)."""
    from python_bindings import integrity
    plain = _project(tmp_path).parameter_path
    before = integrity.parameters_sha256(plain)
    Path(plain).write_text(Path(plain).read_text() + TABLE)
    assert integrity.parameters_sha256(plain) == before
    Path(plain).write_text(Path(plain).read_text().replace("g = 9.81", "g = 9.80"))
    assert integrity.parameters_sha256(plain) != before


def _reads(model) -> list:
    """The observer input columns of a model's measured signals (an output NAME is read as y_NAME)."""
    kinds = noise.measured_signals(model)
    return [f"y_{s}" if k == "output" else s for s, k in kinds.items()]


def test_starters_declare_the_levels_the_float32_build_took(tmp_path):
    """Every starter's [sensor_noise] holds the levels its float32 build took before (the example's
    [precision] noise, else the family's): the float32 tolerance of a starter is unchanged, and its
    excitation run carries noise by default."""
    from types import SimpleNamespace
    from codegen import families
    from codegen.project import observer_file as observers, starter
    from codegen.targets.float32 import input_noise
    for name in families.names():
        family = families.get(name)
        if not family.example:
            continue
        example = observers.get(family.example)
        config = observers.get(str(starter.write(tmp_path / name, family)))
        params = load_parameters(config.parameter_path)
        assert params.sensor_noise, name
        build = SimpleNamespace(input_names=_reads(example.load_model()))
        assert input_noise(config, build) == input_noise(example, build), name


def test_a_precision_noise_that_disagrees_with_the_sensor_table_is_refused(tmp_path):
    from types import SimpleNamespace
    from codegen import families
    from codegen.project import observer_file as observers, starter
    from codegen.targets.float32 import input_noise
    family = next(families.get(f) for f in families.names() if families.get(f).example)
    path = starter.write(tmp_path, family)
    config = observers.get(str(path))
    model = config.load_model()
    declared = noise.declared(model, load_parameters(config.parameter_path))
    sig, std = next(iter(declared.items()))
    col = f"y_{sig}" if noise.measured_signals(model)[sig] == "output" else sig
    build = SimpleNamespace(input_names=_reads(model))
    text = path.read_text()
    assert "[precision]" not in text       # the first starter's example declares no [precision] noise
    path.write_text(text + f"\n[precision]\nnoise = {{ {col} = {std!r} }}\n")
    assert input_noise(observers.get(str(path)), build)[col] == std           # agreeing: read, the same level
    path.write_text(text + f"\n[precision]\nnoise = {{ {col} = {3 * std!r} }}\n")
    with pytest.raises(ConfigurationError, match=rf"{path.name}: \[precision.noise\] {col} = {3 * std:g} disagrees with "
                                                 rf"the sensor noise {std:g} that \[sensor_noise\] of .*parameters.toml "
                                                 rf"declares for it"):
        input_noise(observers.get(str(path)), build)


def test_the_header_says_how_the_run_was_measured(tmp_path, monkeypatch):
    config = _project(tmp_path, TABLE)
    assert ", sensor noise as declared, " in validate.header("obs", _run(config, monkeypatch))
    assert ", noise free (--noise-free), " in validate.header("obs", _run(config, monkeypatch, noise=False))


def test_noise_free_is_for_the_excitation_scenario():
    """A family's own scenarios carry their paper's noise: --noise-free there is refused, not ignored."""
    from codegen import families
    from codegen.contract.capabilities import Scenarios
    family = next(families.get(f) for f in families.names()
                  if families.get(f).example and isinstance(families.get(f), Scenarios))
    scenario = family.demo_scenarios[0]
    with pytest.raises(ConfigurationError, match=rf"--noise-free: scenario '{scenario}' is the {family.name} family's"):
        validate.run_scenario(family.example, scenario, noise=False)


@pytest.mark.slow       # designs, generates, compiles and runs a starter (about a minute)
def test_a_starter_validates_with_its_declared_noise(tmp_path, capsys):
    """A starter (`uiogen new`) declares its sensors' noise; validate adds it by default (other figures
    than --noise-free, the same ones run again), and with sensors 100 x noisier, edited without a new
    design or build (the table is no design input), the unknown input's estimate is named as carrying
    no information and --fail-uninformative exits 3."""
    import tomllib
    from codegen import families
    from codegen.project import observer_file as observers, starter
    family = next(families.get(f) for f in families.names() if families.get(f).example)
    path = starter.write(tmp_path, family)
    for argv in (["design", str(path), "--update"], ["generate", str(path)], ["build", str(path)]):
        assert cli.main(argv) == 0, argv
    config = observers.get(str(path))
    unknown = [str(d) for d in config.load_model().unknown_inputs]
    noisy = validate.run_scenario(config, "excitation", duration=8.0)
    again = validate.run_scenario(config, "excitation", duration=8.0)
    free = validate.run_scenario(config, "excitation", duration=8.0, noise=False)
    assert noisy["noise"]["mode"] == "declared" and noisy["noise"]["levels"] and free["noise"]["mode"] == "off"
    assert {s: r["rms"] for s, r in noisy["observer"].items()} == {s: r["rms"] for s, r in again["observer"].items()}
    for d in unknown:
        assert noisy["observer"][d]["rms"] > free["observer"][d]["rms"] > 0, d
        assert noisy["observer"][d]["no_information"] is False, d
    params = Path(config.parameter_path)
    text = params.read_text()
    levels = tomllib.loads(text)["sensor_noise"]
    params.write_text(text[:text.index("[sensor_noise]")] + "[sensor_noise]\n"
                      + "".join(f"{name} = {100 * std!r}\n" for name, std in levels.items()))
    capsys.readouterr()
    assert cli.main(["validate", str(path), "--scenario", "excitation", "--duration", "8", "--json",
                     "--fail-uninformative"]) == 3
    data = json.loads(capsys.readouterr().out)
    assert set(unknown) <= set(data["uninformative"]), data["uninformative"]
    assert data["noise"]["levels"] == pytest.approx({k: 100 * v for k, v in noisy["noise"]["levels"].items()})


def _misspelt_starter(tmp_path):
    """The first example's starter with its first [sensor_noise] name misspelt (its underscores dropped,
    or an x appended): (observer file, parameter file, the right name, the misspelt one)."""
    import re
    import tomllib
    from codegen import families
    from codegen.project import observer_file as observers, starter
    family = next(families.get(f) for f in families.names() if families.get(f).example)
    path = starter.write(tmp_path, family)
    params = Path(observers.get(str(path)).parameter_path)
    text = params.read_text()
    right = next(iter(tomllib.loads(text)["sensor_noise"]))
    wrong = right.replace("_", "") if "_" in right else right + "x"
    params.write_text(re.sub(rf"^{right} = ", f"{wrong} = ", text, count=1, flags=re.M))
    return path, params, right, wrong


def test_a_misspelt_noise_name_is_refused_at_design(tmp_path, capsys, monkeypatch):
    """A [sensor_noise] name that is no measured signal is refused by `uiogen design` as validate and the
    float32 build refuse it (one line naming the file, the key and the signal meant), before any solve."""
    from codegen import pipeline
    path, params, right, wrong = _misspelt_starter(tmp_path)
    monkeypatch.setattr(pipeline, "solve", lambda *a, **k: pytest.fail("solved a design with a misspelt noise name"))
    capsys.readouterr()
    assert cli.main(["design", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith(f"uiogen: error: ConfigurationError: {params}: [sensor_noise] {wrong} = "), err
    assert err.endswith(f"(did you mean '{right}'?)"), err


@pytest.mark.slow       # one design of a starter (about 12 s)
def test_the_name_the_refusal_suggests_designs(tmp_path):
    """The advice applied (the name it suggests) designs; the table stays out of the design hash."""
    import re
    from python_bindings import integrity
    path, params, right, wrong = _misspelt_starter(tmp_path)
    misspelt = integrity.parameters_sha256(params)
    params.write_text(re.sub(rf"^{wrong} = ", f"{right} = ", params.read_text(), count=1, flags=re.M))
    assert integrity.parameters_sha256(params) == misspelt
    assert cli.main(["design", str(path)]) == 0
