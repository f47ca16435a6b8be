"""`uiogen fit` with a prior and cross-validation, on the second car (the built-in
niki_sideslip_nonlinear_tyre) and on parameter files with hostile [prior] tables.

The figures are the committed fit's on the shared run of the GTI "Niki" (the whole run is identification
data; other runs of the car judge and are not shared): tolerances a change of the fit, the design or the
step breaks.
"""
import re

import numpy as np
import pytest

from codegen import cli
from codegen.errors import ConfigurationError
from codegen.families.nonlinear_tyre_observer import fit
from codegen.model import load_parameters
from codegen.project import observer_file as observers
from codegen.validation import stanford

from conftest import require_shared

NIKI = "niki_sideslip_nonlinear_tyre"


def test_the_averages_span_the_same_time_at_every_sample_rate():
    """0.21 s of samples, odd (centred): 21 at 100 Hz, 43 at 200 Hz; a 200 Hz log was averaged over
    0.105 s when the window was a sample count."""
    assert fit.window(0.01) == fit.WINDOW == 21
    assert fit.window(0.005) == 43
    assert fit.window(0.001) == 211
    assert fit.window(1.0) == 1


def _params(tmp_path, prior: str):
    base = observers.get(NIKI).parameter_path.read_text()
    text = re.sub(r"\n\[prior\]\n.*?(?=\n\[scheduling)", "\n", base, flags=re.S)
    path = tmp_path / "parameters.toml"
    path.write_text(text + "\n[prior]\n" + prior)
    return path


def test_the_prior_table_reads_published_values_with_their_uncertainty(tmp_path):
    p = load_parameters(_params(tmp_path, 'C_f = { value = 1.1e5, rel_sigma = 0.2, source = "datasheet" }\n'))
    assert p.prior == {"C_f": {"value": 110000.0, "rel_sigma": 0.2, "source": "datasheet"}}
    assert load_parameters(observers.get(NIKI).parameter_path).prior["C_r"]["value"] == 180000.0


@pytest.mark.parametrize("prior, match", [
    ('C_ff = { value = 1.1e5, rel_sigma = 0.2 }\n', r"\[prior\].*C_ff.*did you mean 'C_f'"),
    ('C_f = { value = 1.1e5 }\n', r"prior\.C_f.*rel_sigma"),
    ('C_f = { value = 1.1e5, rel_sigma = -0.2 }\n', r"prior\.C_f.*rel_sigma.*> 0"),
    ('C_f = { value = 1.1e5, rel_sigma = 0.2, sigma = 3.0 }\n', r"prior\.C_f.*sigma"),
    ('C_f = 110000.0\n', r"\[prior\].*C_f.*inline table"),
])
def test_a_wrong_prior_is_one_typed_line_naming_the_file_and_key(tmp_path, prior, match):
    path = _params(tmp_path, prior)
    with pytest.raises(ConfigurationError, match=match) as err:
        load_parameters(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


@pytest.mark.slow       # two candidates on five folds of 17,631 samples, ten designs, the EKF: about 30 s
def test_niki_fit_judges_published_against_fitted_on_held_out_folds_and_reproduces_its_files():
    """`uiogen fit niki_sideslip_nonlinear_tyre --data niki --samples 0:17631 --folds 5` writes exactly the
    committed files: on five contiguous held-out folds the published stiffnesses (friction from the log)
    predict the sideslip better than the three fitted numbers, and the observer built on them is at or
    below the same-tyre EKF on the pooled folds."""
    require_shared(stanford.NIKI_PATH, "shared run of the second car")
    cfg = observers.get(NIKI)
    r = fit.fit(cfg, "niki", "0:17631", folds=5)
    for path, text in fit.files(cfg, r).items():
        assert path.read_text() == text, f"{path} differs from the fit"
    assert r["choice"] == "published" and r["window_samples"] == 43
    assert r["parameters"] == {"C_f": 110000.0, "C_r": 180000.0, "mu_f": 1.305, "mu_r": 1.305}
    cand = r["candidates"]
    assert cand["published"]["pooled_rms_deg"] < cand["fitted"]["pooled_rms_deg"] - 0.03
    assert r["cross_validated_rms_deg"] == pytest.approx(0.4109, abs=0.002)
    assert r["cross_validated_rms_deg"] <= r["peer_cross_validated_rms_deg"]
    assert r["peer_cross_validated_rms_deg"] == pytest.approx(0.4138, abs=0.002)
    # the published friction is not this day's: the log's combined acceleration says at least 1.04
    assert r["mu_reached"] == pytest.approx(1.043, abs=0.002) and r["parameters"]["mu_f"] > r["mu_reached"]
    # each fold's friction is fitted without it; the jackknife spreads them into a standard error
    mus = np.array([row["parameters"]["mu_f"] for row in r["cross_validation"]])
    assert len(set(mus)) > 1 and r["uncertainty"]["C_f"] == 0.0
    assert r["uncertainty"]["mu_f"] == pytest.approx(np.sqrt(4 / 5 * np.sum((mus - mus.mean()) ** 2)), rel=1e-3)
    header, rows = r["table"]["header"], r["table"]["rows"]
    assert header[-1].startswith("EKF (published tyre)") and len(rows) == 5 + 2
    assert rows[-1][0] == "0–17630: published (written)"


def test_the_fit_is_the_same_on_any_number_of_processes(capsys):
    """--jobs spreads the folds' designs and the peers' Kalman runs over processes: the result, every
    number of it, is the one a single process gives; a count below 1 is one typed line."""
    require_shared(stanford.NIKI_PATH, "shared run of the second car")
    cfg = observers.get(NIKI)
    one = fit.fit(cfg, "niki", "0:12000", folds=2, jobs=1)
    two = fit.fit(cfg, "niki", "0:12000", folds=2, jobs=2)
    assert repr(one) == repr(two)
    assert len(one["cross_validation"]) == 2 and "peer_cross_validated_rms_deg" in one
    assert cli.main(["fit", NIKI, "--data", "niki", "--samples", "0:6000", "--jobs", "0"]) == 2
    err = capsys.readouterr().err
    assert "--jobs 0: an integer >= 1" in err and "Traceback" not in err


@pytest.mark.slow       # two designs of the built-in Ferrari, a few seconds each
def test_the_noise_bound_objective_certifies_a_lower_bound_at_the_levels():
    """objective = "noise_bound" minimizes the RMS bound at the noise levels over the gains: its certified
    bound is at most the gamma design's (whose gains the same problem could have chosen), and its uniform
    gain stays certified (eta = the largest multiplier)."""
    import dataclasses
    from codegen import families
    from codegen.design.solver import FreshSolver
    family = families.get("nonlinear_tyre_observer")
    cfg = observers.get("stanford_sideslip_nonlinear_tyre")
    g = family.build(cfg, FreshSolver())
    n = family.build(dataclasses.replace(cfg, design={**cfg.design, "objective": "noise_bound"}), FreshSolver())
    fg, fn = g.figures(), n.figures()
    assert fn["bound_deg_at_levels"] < fg["bound_deg_at_levels"]
    assert fn["gamma_deg"] >= fg["gamma_deg"] * (1 - 1e-3)
    assert not np.allclose(n.L, g.L)


@pytest.mark.slow       # a fit on 13,750 samples, the observer and both peers on two runs: about 15 s
def test_identify_on_one_run_and_judge_on_another(tmp_path, capsys):
    """`uiogen fit ... --judge OTHER --plot FILE --report DIR`: the observer designed with the fitted numbers
    and its same-tyre EKF and UKF run on the fit range and on another run (here the rest of the shared half,
    written as a file of its own: each estimator starts from its initial state there), printed beside each
    other, in --json, drawn, and on an HTML page."""
    import gzip
    import json
    require_shared(stanford.STANFORD_PATH, "shared Stanford log")
    lines = gzip.open(stanford.STANFORD_PATH, "rt").read().splitlines()
    other = tmp_path / "other_run.csv"
    other.write_text("\n".join([lines[0], *lines[1 + 13750:]]) + "\n")
    name, png = "stanford_sideslip_nonlinear_tyre", tmp_path / "runs.png"
    assert cli.main(["fit", name, "--data", "stanford", "--samples", "0:13750", "--folds", "0", "--judge", str(other),
                     "--plot", str(png), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    fit_run, judged = r["runs"]
    assert fit_run["samples"] == 13750 and judged["samples"] == 13750 and judged["data"] == str(other)
    assert fit_run["estimators"]["observer"]["rms_deg"] == pytest.approx(r["observer_beta_rms_deg"], rel=1e-12)
    assert judged["estimators"]["observer"]["rms_deg"] == pytest.approx(0.2597, abs=0.002)
    assert judged["estimators"]["ekf_nonlinear_tyre"]["rms_deg"] == pytest.approx(0.2704, abs=0.002)
    assert set(judged["estimators"]) == {"observer", "ekf_nonlinear_tyre", "ukf_nonlinear_tyre"}
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the text table names both runs; --plot without a run to judge is one typed line
    page = tmp_path / "report" / "index.html"
    assert cli.main(["fit", name, "--data", "stanford", "--samples", "0:13750", "--folds", "0", "--judge", str(other),
                     "--report", str(page.parent)]) == 0
    out = capsys.readouterr().out
    assert "stanford (the fit, 0:13750)" in out and "other_run.csv" in out
    html = page.read_text()               # the page: the runs' table, their figure beside it, the output
    assert html.count("<tr>") == 3 and str(other) in html and 'src="runs.png"' in html
    assert (page.parent / "runs.png").read_bytes()[:4] == b"\x89PNG" and "uiogen fit" in html
    assert cli.main(["fit", name, "--data", "stanford", "--samples", "0:13750", "--plot", str(png)]) == 2
    err = capsys.readouterr().err
    assert "--plot" in err and "--judge" in err and len(err.strip().splitlines()) == 1
    assert cli.main(["fit", name, "--data", "stanford", "--samples", "0:13750", "--judge", "/nonexistent.csv"]) == 2
    assert "DatasetError" in capsys.readouterr().err


@pytest.mark.slow       # two settings x two tyre sets x two folds on 3000 samples: eight designs, about 25 s
def test_fit_chooses_design_settings_on_the_held_out_folds_and_writes_the_best(tmp_path, capsys):
    """`uiogen fit ... --folds 2 --choose design.decay_fraction=[0.1, 0.2] --write` in a starter: every
    combination is cross-validated with both tyre sets, the one with the lowest pooled held-out RMS is
    written into the observer file's [design] beside the noise levels; a setting outside [design], or
    a choice without folds, is one typed line."""
    import json
    require_shared(stanford.STANFORD_PATH, "shared Stanford log")
    folder = tmp_path / "car"
    assert cli.main(["new", str(folder), "--family", "nonlinear_tyre_observer", "--name", "mine"]) == 0
    obs = folder / "mine.toml"
    capsys.readouterr()
    args = ["fit", str(obs), "--data", "stanford", "--samples", "9000:12000", "--folds", "2"]
    assert cli.main([*args, "--choose", "design.decay_fraction=[0.1, 0.2]", "--write", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    table = r["settings"]
    assert table["keys"] == ["design.decay_fraction"] and [row[0] for row in table["rows"]] == [0.1, 0.2]
    best = min(table["rows"], key=lambda row: min(row[1:3]))
    assert r["design"]["decay_fraction"] == best[0]
    assert r["cross_validated_rms_deg"] == pytest.approx(min(best[1:3]), rel=1e-12)
    written = re.search(r"^decay_fraction = ([0-9.]+)", obs.read_text(), re.M)
    assert float(written.group(1)) == best[0]
    for extra, match in ((["--choose", "parameters.C_f=[1e5]"], "chooses \\[design\\] settings only"),
                         (["--choose", "design.decay_fraction=[0.1]", "--folds", "0"], "needs --folds")):
        assert cli.main([*args[:-2], *extra] if "--folds" in extra else [*args, *extra]) == 2
        err = capsys.readouterr().err
        assert re.search(match, err) and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_an_axle_missing_a_field_is_one_typed_line_naming_the_model_the_axle_and_the_field(tmp_path, capsys):
    """A user's model written against an older contract (its Axle without peak_symbol) was an
    AttributeError traceback inside the representation; now design and fit say which axle of which
    model file lacks which field."""
    folder = tmp_path / "car"
    assert cli.main(["new", str(folder), "--family", "nonlinear_tyre_observer", "--name", "mine"]) == 0
    model = folder / "model.py"
    text = model.read_text()
    older = ("from dataclasses import dataclass\n\n\n"
             "@dataclass(frozen=True)\nclass Axle:      # last month's contract\n"
             + "".join(f"    {f}: object\n" for f in ("name", "law", "projection", "slip", "inverse", "sliding", "peak",
                                                      "stiffness", "friction")) + "\n\n")
    for old, new in (("from codegen.model import Axle, ModelDefinition, SchedulingSignal\n",
                      older + "from codegen.model import ModelDefinition, SchedulingSignal\n"),
                     ("tyres.fiala_sliding_slip(C_f, F_PEAK[0]), F_PEAK[0], F_maxf",
                      "tyres.fiala_sliding_slip(C_f, F_PEAK[0]), F_maxf"),
                     ("tyres.fiala_sliding_slip(C_r, F_PEAK[1]), F_PEAK[1], F_maxr",
                      "tyres.fiala_sliding_slip(C_r, F_PEAK[1]), F_maxr")):
        assert old in text
        text = text.replace(old, new)
    model.write_text(text)
    capsys.readouterr()
    for verb in (["design", str(folder / "mine.toml")],
                 ["fit", str(folder / "mine.toml"), "--data", "stanford", "--samples", "0:1000", "--folds", "0"]):
        if verb[0] == "fit":
            require_shared(stanford.STANFORD_PATH, "shared Stanford log")
        assert cli.main(verb) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err and "AttributeError" not in err
        assert str(model) in err and "AXLES[0] ('front')" in err and "has no peak_symbol" in err


def test_the_axle_contract_is_a_typed_class_that_checks_its_fields(tmp_path):
    """codegen.model.Axle: the built-in model builds its axles with it; a field of the wrong kind (a number
    where the stiffness parameter is meant) is one ModelDefinitionError at the model's import, naming the
    model file, the axle and the field."""
    import subprocess
    import sys
    from codegen.model import Axle
    from conftest import ROOT
    assert all(isinstance(a, Axle) for a in observers.get("niki_sideslip_nonlinear_tyre").load_model_module().AXLES)
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "new", str(tmp_path / "p"), "--family",
                           "nonlinear_tyre_observer", "--name", "mine"], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    model = tmp_path / "p" / "model.py"
    text = model.read_text()
    assert "from codegen.model import Axle" in text and "F_maxf, C_f, mu_f)" in text
    model.write_text(text.replace("F_maxf, C_f, mu_f)", "F_maxf, 110000.0, mu_f)"))
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "design", str(tmp_path / "p" / "mine.toml")],
                          capture_output=True, text=True, cwd=ROOT)
    err = proc.stderr.strip()
    assert proc.returncode == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert "ModelDefinitionError" in err and str(model) in err and "Axle 'front': stiffness = 110000.0" in err


def test_a_folds_parametric_step_is_the_emitted_step():
    """The folds of a fit run the step compiled once per model with the parameters passed in
    (``step_function(parametric=True)``): at random points of every box, with other tyre numbers than
    the committed ones, beyond the certified set (the fallback) and outside the boxes, it gives the step
    the C is emitted from to the last few bits."""
    import dataclasses
    from codegen.design.solver import FreshSolver
    from codegen.families.nonlinear_tyre_observer.build import build
    cfg = observers.get(NIKI)
    params = load_parameters(cfg.parameter_path)
    other = dataclasses.replace(params, values={**params.values, "C_f": 95000.0, "mu_f": 1.1, "mu_r": 1.2})
    rng = np.random.default_rng(11)
    for p in (params, other):
        obs = build(cfg, FreshSolver(), params=p)
        emitted, parametric = obs.step_function(), obs.step_function(parametric=True)
        boxes = [b for _, b in obs.rep.input_boxes]
        flagged = 0
        for _ in range(300):
            z = rng.uniform([-3, -1, -3, -1], [3, 1, 3, 1])
            u = [rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo)) for lo, hi in boxes]
            y = [rng.uniform(-12, 12), rng.uniform(-1, 1)]
            v = [rng.uniform(obs.rep.v_x_box[0] - 2, obs.rep.v_x_box[1] + 2)]
            a = [np.array(o.full()).ravel() for o in emitted(z, u, y, v)]
            b = [np.array(o.full()).ravel() for o in parametric(z, u, y, v)]
            flagged += a[1][0] > 0
            np.testing.assert_allclose(b[0], a[0], rtol=1e-12, atol=1e-12)
            assert (a[1][0] > 0) == (b[1][0] > 0)
        assert 30 < flagged < 270             # both branches compared
