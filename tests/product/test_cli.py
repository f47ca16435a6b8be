"""The uiogen command line: JSON outputs for scripts and typed errors with exit code 2."""
import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import HANG_GUARD

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())


def uiogen(*args):
    return subprocess.run([sys.executable, "-m", "codegen.cli", *args], capture_output=True, text=True, cwd=ROOT)


def test_list_json():
    proc = uiogen("list", "--json")
    assert proc.returncode == 0
    assert "lpv_linf_driver_torque" in [r["name"] for r in json.loads(proc.stdout)]


def test_a_reader_that_closes_the_pipe_gets_no_traceback():
    """`uiogen list | head -1`: the reader closes the pipe before uiogen writes; uiogen stops quietly,
    with the status of a command killed by SIGPIPE (a BrokenPipeError traceback 2 runs in 3 before)."""
    proc = subprocess.Popen([sys.executable, "-m", "codegen.cli", "list"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=ROOT)
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=HANG_GUARD) == 141 and err == "", err


@pytest.mark.slow       # 15 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_design_json_and_artifact(tmp_path):
    out = tmp_path / "design.json"
    proc = uiogen("design", "lpv_linf_driver_torque", "--json", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    for key in ("gamma", "gamma_quadratic", "solve_time_s", "vertices", "worst_min_eig",
                "discrete_contraction_per_step", "discrete_spectral_radius_max"):
        assert key in s
    art = json.loads(out.read_text())
    assert {"P1", "P2", "X", "L1", "L2", "gamma", "polytope", "certificate"} <= set(art)
    # our own artifact passes the external checker, with its own gamma
    proc = uiogen("check-gains", "lpv_linf_driver_torque", "--gains", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert res["cases"]["exact"]["gamma"] <= art["gamma"] * (1 + 1e-6)


@pytest.mark.slow       # 4 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_check_gains_published(published):
    proc = uiogen("check-gains", "lpv_linf_driver_torque", "--gains",
                  str(ROOT.parent / "shared" / "reference" / "seed000_published_design.json"))
    assert proc.returncode == 0 and "PASS" in proc.stdout and "0.00951" in proc.stdout


@pytest.mark.slow       # 6 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_errors_are_typed(tmp_path):
    proc = uiogen("design", "no_such_observer")
    assert proc.returncode == 2 and "UnknownObserverError" in proc.stderr
    bad = tmp_path / "g.json"
    bad.write_text(json.dumps({"P1": [[1]]}))
    proc = uiogen("check-gains", "lpv_linf_driver_torque", "--gains", str(bad))
    assert proc.returncode == 2 and "lack" in proc.stderr


@pytest.mark.slow       # 10 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_sweep_json_and_mistakes():
    proc = uiogen("sweep", "switched_pi_bank_angle", "--set", "design.pole_radius=[29, 100]",
                  "--set", "design.decay_rate=[0]", "--show", "gamma,max_pole_modulus", "--json")
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert [p["outcome"] for p in res["points"]] == ["InfeasibleLMIError", "certified"]
    assert res["points"][1]["gamma"] < 0.013 and res["show"] == ["gamma", "max_pole_modulus"]
    proc = uiogen("sweep", "switched_pi_bank_angle", "--set", "design.pole_radus=[50]")
    assert proc.returncode == 2 and "pole_radus" in proc.stderr and "did you mean 'pole_radius'" in proc.stderr
    assert "Traceback" not in proc.stderr and proc.stdout == ""
    proc = uiogen("sweep", "switched_pi_bank_angle", "--set", "design.pole_radius=[50,")
    assert proc.returncode == 2 and "not a TOML value" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.slow          # a float32 build
def test_build_float32_accepted_and_refused():
    """`uiogen build --float32`: an observer whose certified contraction bounds the float
    rounding within every output's tolerance is built (exit 0, its library on disk, the figures
    per signal printed); one whose margin does not is refused with exit 2 and a one-line typed
    error, the reason (signal, bound, tolerance, margin, the setting that would fix it) above it."""
    ok = uiogen("build", "--float32", "lpv_linf_driver_torque")
    assert ok.returncode == 0, ok.stderr
    assert "lpv_linf_driver_torque: float32 accepted" in ok.stdout
    assert "T_d            bound" in ok.stdout and "N m" in ok.stdout
    from codegen.project import observer_file
    lib = (observer_file.get("lpv_linf_driver_torque").workspace.float32 / "lpv_linf_driver_torque"
           / "liblpv_linf_driver_torque_f32.so")
    assert lib.exists() and f"built {lib}" in ok.stdout
    bad = uiogen("build", "--float32", "stanford_sideslip_nonlinear_tyre")
    assert bad.returncode == 2
    assert "Traceback" not in bad.stderr
    lines = bad.stderr.strip().splitlines()
    assert lines == ["uiogen: error: CertificateError: float32 build refused for stanford_sideslip_nonlinear_tyre "
                     "(the reasons and figures above)"]
    assert "stanford_sideslip_nonlinear_tyre: float32 REFUSED: v_y on stanford log: bound" in bad.stdout
    assert "margin 1 - c = " in bad.stdout and "sliding_fraction" in bad.stdout
    assert "outside the certified set (SCHEDULING_CLAMPED)" in bad.stdout


@pytest.mark.slow       # two short excitation runs of a compiled observer
def test_validate_refuses_what_it_cannot_do_with_a_typed_error(tmp_path, capsys, monkeypatch):
    """A --duration too short for the metrics (or not finite), --plant commonroad on the excitation scenario (which
    runs the model's own equations: the option was silently ignored) and --plot without matplotlib
    (a wheel installs none) are typed errors naming the option, never a traceback."""
    from codegen import cli
    name = "lpv_linf_driver_torque"
    for args, match in ((["--duration", "-3"], "--duration -3.0: allowed: a number of seconds above 2"),
                        (["--duration", "1.5"], "--duration 1.5: allowed: a number of seconds above 2"),
                        (["--duration", "nan"], "--duration nan"),
                        (["--plant", "commonroad"], "--plant commonroad: the excitation scenario runs on")):
        assert cli.main(["validate", name, "--scenario", "excitation", *args]) == 2
        err = capsys.readouterr().err
        assert "ConfigurationError" in err and match in err and "Traceback" not in err
    assert cli.main(["validate", name, "--scenario", "excitation", "--duration", "3"]) == 0
    capsys.readouterr()
    monkeypatch.setitem(sys.modules, "matplotlib", None)         # import matplotlib raises ImportError
    plot = tmp_path / "x.png"
    assert cli.main(["validate", name, "--scenario", "excitation", "--duration", "3", "--plot", str(plot)]) == 2
    err = capsys.readouterr().err
    assert "UnsupportedError" in err and "uiogen[validation]" in err and "Traceback" not in err
    assert not plot.exists()


def test_bench_and_demo_without_the_built_observers_say_so_once(tmp_path, monkeypatch, capsys):
    """An installed uiogen in an empty folder has none of the built-in observers built: `uiogen bench`
    and `uiogen demo` say so once, before any work (bench failed on the first observer with 'run uiogen
    generate X', demo with a FileNotFoundError traceback)."""
    from codegen import cli
    from codegen.project import observer_file as observers
    from python_bindings.workspace import Workspace
    monkeypatch.setattr(Workspace, "extension", lambda self, name: tmp_path / f"_{name}.so")
    n = len(observers.names())
    for verb in ("bench", "demo"):
        assert cli.main([verb]) == 2
        err = capsys.readouterr().err
        assert f"UnsupportedError: uiogen {verb} runs every built-in observer; {n} of {n} are not built here" in err
        assert "`uiogen generate` and `uiogen build` first" in err and "Traceback" not in err


def test_a_verb_that_needs_an_extra_names_it(monkeypatch, capsys):
    """A wheel installs no extra: a verb whose run imports CommonRoad's vehicle models (uiogen demo,
    validate on a named scenario) said ModuleNotFoundError in a traceback; now the extra to install."""
    from codegen import cli
    # every import of vehiclemodels raises ImportError: its submodules too, which an earlier test in the
    # same worker may have imported (``from vehiclemodels.init_mb import ...`` finds a cached submodule
    # without looking at its package)
    for name in [m for m in sys.modules if m == "vehiclemodels" or m.startswith("vehiclemodels.")] + ["vehiclemodels"]:
        monkeypatch.setitem(sys.modules, name, None)
    assert cli.main(["validate", "interconnected_uio_ford_escort", "--scenario", "satory", "--plant", "commonroad",
                     "--duration", "3"]) == 2
    err = capsys.readouterr().err
    assert "UnsupportedError: vehiclemodels is not installed" in err and "uiogen[validation]" in err
    assert "Traceback" not in err


@pytest.mark.slow       # a 3 s run of the interconnected observer
def test_a_run_cut_short_prints_a_dash_where_a_figure_is_undefined(capsys):
    """Cut to 3 s, the Satory run leaves 1 s after the settle time with several truths at 0: their
    RMSE % of max |truth| is undefined, and the table and the paper targets skip them (a TypeError
    traceback before)."""
    from codegen import cli
    assert cli.main(["validate", "interconnected_uio", "--scenario", "satory", "--duration", "3"]) == 0
    out = capsys.readouterr().out
    assert "       - (" in out and "issue target mu = 1" in out


def test_without_the_shared_log_the_stanford_shorthand_and_the_demo_say_so(tmp_path, monkeypatch, capsys):
    """An installed uiogen has no ../shared beside it: `--data stanford` and `uiogen demo` (which ends
    on that log, after minutes of simulation) say where the log was looked for, before any work."""
    from codegen import cli
    from codegen.validation import stanford
    monkeypatch.setattr(stanford, "STANFORD_PATH", tmp_path / "shared" / "run.csv.gz")
    assert cli.main(["validate", "stanford_sideslip", "--data", "stanford"]) == 2
    err = capsys.readouterr().err
    assert "DatasetError: 'stanford' is the shared log beside a source checkout" in err and "own path" in err
    assert cli.main(["demo"]) == 2
    err = capsys.readouterr().err
    assert "UnsupportedError: uiogen demo ends on the shared Stanford log" in err and "Traceback" not in err


def _fake_sweep(monkeypatch, figures):
    """sweep.point answers at once: the first point refused, the others certified with ``figures``."""
    from codegen.analysis import sweep
    calls = []

    def point(name, overrides):
        calls.append(overrides)
        if len(calls) == 1:
            return {"settings": overrides, "outcome": "InfeasibleLMIError", "message": "no", "seconds": 0.0}
        return {"settings": overrides, "outcome": "certified", **figures, "certified_contraction_per_step": 0.9,
                "seconds": 0.0}
    monkeypatch.setattr(sweep, "point", point)
    return calls


def test_sweep_show_names_an_unknown_figure_and_defaults_to_what_the_family_reports(monkeypatch, capsys):
    """--show gama printed an empty column (and the default gamma column was empty for ts_fuzzy_uio,
    which reports no gamma): a name the family does not report is a ConfigurationError with a
    did-you-mean and the figures there are; without --show, gamma only where the family has it."""
    from codegen import cli
    _fake_sweep(monkeypatch, {"gamma": 0.5, "rules": 4})
    assert cli.main(["sweep", "lpv_linf_driver_torque", "--set", "design.alpha=[1, 2]", "--show", "gama"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("uiogen: error: ConfigurationError: --show gama: observer "
                                               "lpv_linf_driver_torque (linf_uio) reports no figure 'gama'")
    assert "(did you mean 'gamma'?)" in err[0] and "its figures: gamma, rules, certified_contraction_per_step" in err[0]
    # ts_fuzzy_uio reports no gamma: the default column is the certified contraction, the header printed once
    _fake_sweep(monkeypatch, {"rules": 4})
    assert cli.main(["sweep", "ts_fuzzy_uio", "--set", "design.alpha=[1, 2]"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 3 and "certified_contraction_per_step" in out[0] and "gamma" not in out[0]
    assert "InfeasibleLMIError" in out[1]
    assert out[2].split()[-1] == "0.9"
    _fake_sweep(monkeypatch, {"gamma": 0.5})
    assert cli.main(["sweep", "lpv_linf_driver_torque", "--set", "design.alpha=[1, 2]", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["show"] == ["gamma"]
