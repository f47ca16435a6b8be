"""One set of checks for every log (issue 25, probe 1): a user's column map and the shared format
get each mapped column checked against its declared unit's plausible range and the physics of the
observer's model (codegen/validation/log_checks.py) before any estimate is reported.

The probes run the ``stanford_sideslip`` observer (its committed lock and built extension: the
observer file is copied under its own name with a ``[data]`` table and ``--project`` the checkout;
the map is not part of the design) over a synthetic drive with consistent planar rigid-body
physics (always available) and over the shared real log. Before the checks, every probe below
exited 0: a_y declared in g on a log in m/s^2 gave beta RMS 42.8 deg and "0 flagged".
"""
import json
import math
import subprocess
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from codegen.errors import DatasetError
from codegen.model import load_parameters
from codegen.project import observer_file as observers
from codegen.project.columns import model_unit
from codegen.validation import log_checks as L
from codegen.validation import logs
from codegen.validation import stanford as S

from conftest import require_shared

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
NAME = "stanford_sideslip"
MAP = {"delta": ("delta", "rad"), "y_r": ("yaw_rate", "rad/s"), "y_a_y": ("ay", "m/s^2"), "v_x": ("vx", "m/s")}


def _synthetic(n=3000, dt=0.01, vx0=30.0, r_amp=0.25, seed=0) -> dict:
    """A drive of the Stanford format: planar kinematics at the CoG (a_y = dv_y/dt + v_x r) and a
    road-wheel angle from the steady-state single track of the observer's car (wheelbase 2.4 m,
    understeer 0.0017 s^2/m: the linear model of stanford_race_car.toml), sensor noise."""
    rng = np.random.default_rng(seed)
    t = 10.0 + dt * np.arange(n)
    w1, w2 = 2 * math.pi * 0.05, 2 * math.pi * 0.15
    vx = vx0 + 4.0 * np.sin(w1 * t)
    r = r_amp * np.sin(w2 * t)
    vy = 0.3 * np.sin(w2 * t + 0.6)
    delta = r * (2.4 + 0.0017 * vx ** 2) / vx
    noise = lambda s: s * rng.standard_normal(n)               # noqa: E731
    return {"t": t, "vx": vx, "vy": vy, "beta_true": np.arctan2(vy, vx),
            "ax": 4.0 * w1 * np.cos(w1 * t) - vy * r + noise(0.05),
            "ay": 0.3 * w2 * np.cos(w2 * t + 0.6) + vx * r + noise(0.05),
            "yaw_rate": r + noise(0.001), "yaw_acc": r_amp * w2 * np.cos(w2 * t) + noise(0.02),
            "delta": delta, "delta_fl": delta, "delta_fr": delta}


def _write(path: Path, cols: dict) -> Path:
    names = list(cols)
    rows = np.column_stack([cols[c] for c in names])
    with open(path, "w") as fh:
        fh.write(",".join(names) + "\n")
        for row in rows:
            fh.write(",".join(repr(float(v)) for v in row) + "\n")
    return path


def _real(path: Path) -> Path:
    """The shared real log, plain."""
    import gzip
    require_shared(S.STANFORD_PATH, "shared Stanford log")
    path.write_bytes(gzip.decompress(S.STANFORD_PATH.read_bytes()))
    return path


def _observer(folder: Path, **changes) -> Path:
    """stanford_sideslip's observer file with a [data] table mapping the Stanford columns;
    ``changes``: INPUT = "inline table" replacing its entry."""
    text = (ROOT / "model_defs" / "observers" / f"{NAME}.toml").read_text()
    params = re.search(r'(?m)^parameters = "([^"]+)"', text).group(1)       # an observer file of one's own
    (folder / params).write_text((ROOT / "model_defs" / "params" / params).read_text())   # names its own file
    entries = {k: f'{{ column = "{c}", unit = "{u}" }}' for k, (c, u) in MAP.items()}
    entries.update(changes)
    text += "\n[data]\ntime = \"t\"\n\n[data.inputs]\n" + "".join(f"{k} = {v}\n" for k, v in entries.items())
    text += '\n[data.truth]\nbeta = { column = "beta_true", unit = "rad" }\n'
    path = folder / f"{NAME}.toml"
    path.write_text(text)
    return path


def _cli(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "codegen.cli", *args], capture_output=True, text=True, cwd=ROOT)


def _validate(observer: Path, log: Path, *extra) -> subprocess.CompletedProcess:
    return _cli("validate", str(observer), "--data", str(log), "--project", str(ROOT), *extra)


def _one_line_error(proc) -> str:
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    err = proc.stderr.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


@pytest.fixture(params=["synthetic", "real"])
def log(request, tmp_path):
    path = tmp_path / "log.csv"
    return _write(path, _synthetic()) if request.param == "synthetic" else _real(path)


# --- a consistent log: every relation judged and holding, the same estimates as the shared format ---------

@pytest.mark.slow       # 5 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_a_consistent_log_passes_every_check(tmp_path, log):
    proc = _validate(_observer(tmp_path), log, "--json")
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert res["warnings"] == []
    kinds = {c["kind"]: c for c in res["log_checks"]}
    assert set(kinds) == {"identity", "steady state"}                  # a_y = v_x (dbeta/dt + r); r(delta, v_x)
    assert all(c["verdict"] == "ok" for c in res["log_checks"]), res["log_checks"]
    assert 0.95 < kinds["identity"]["ratio"] < 1.05


@pytest.mark.slow       # 4 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_the_column_map_and_the_shared_format_agree(tmp_path):
    log = _write(tmp_path / "log.csv", _synthetic())
    mapped = logs.run(observers.get(str(_observer(tmp_path)), project=ROOT), str(log))
    shared = logs.run(NAME, str(log))
    assert np.array_equal(mapped["signals"]["beta"], shared["signals"]["beta"])         # the same C step, inputs
    assert [c["ratio"] for c in mapped["log_checks"]] == pytest.approx([c["ratio"] for c in shared["log_checks"]])


# --- the probes: one column wrong -----------------------------------------------------------------

@pytest.mark.slow       # runs a compiled extension (the fast lane has no build)
def test_ay_declared_in_g_on_a_log_in_m_s2(tmp_path, log):
    err = _one_line_error(_validate(_observer(tmp_path, y_a_y='{ column = "ay", unit = "g" }'), log))
    assert "column 'ay' (y_a_y, declared g)" in err and 'unit = "m/s^2"' in err, err


@pytest.mark.slow       # runs a compiled extension (the fast lane has no build)
def test_delta_declared_in_degrees_on_a_log_in_radians(tmp_path, log):
    err = _one_line_error(_validate(_observer(tmp_path, delta='{ column = "delta", unit = "deg" }'), log))
    assert "column 'delta' (delta, declared deg)" in err and "steady state" in err, err
    assert "'delta' is in rad, not deg" in err and 'unit = "rad"' in err, err


@pytest.mark.slow       # runs a compiled extension (the fast lane has no build)
def test_yaw_rate_mapped_to_the_yaw_acceleration(tmp_path, log):
    err = _one_line_error(_validate(_observer(tmp_path, y_r='{ column = "yaw_acc", unit = "rad/s" }'), log))
    assert err.count("column '") == 1 and "column 'yaw_acc' (y_r" in err, err
    assert "wrong column" in err and "correlation" in err, err


@pytest.mark.parametrize("change, column, cause", [
    (dict(v_x='{ column = "vx", unit = "km/h" }'), "vx", "'vx' is in m/s, not km/h"),
    (dict(y_r='{ column = "yaw_rate", unit = "deg/s" }'), "yaw_rate", "'yaw_rate' is in rad/s, not deg/s"),
    (dict(y_a_y='{ column = "ay", unit = "m/s^2", scale = -1.0 }'), "ay", "'ay' has the opposite sign"),
], ids=["speed-in-kmh", "yaw-rate-deg-s", "ay-sign"])
@pytest.mark.slow       # runs a compiled extension (the fast lane has no build)
def test_other_single_column_mistakes_name_the_column_and_cause(tmp_path, log, change, column, cause):
    err = _one_line_error(_validate(_observer(tmp_path, **change), log))
    assert f"column {column!r}" in err and cause in err, err


@pytest.mark.slow       # 5 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_a_steering_ratio_slip_is_a_flagged_warning(tmp_path, log):
    """delta x 1.5 through the column map: the yaw rate is 0.55 x the model's steady state. The
    log's scale or the model's steering gain: ambiguous, so a warning in the report and the JSON."""
    observer = _observer(tmp_path, delta='{ column = "delta", unit = "rad", scale = 1.5 }')
    res = json.loads(_validate(observer, log, "--json").stdout)
    assert len(res["warnings"]) == 1, res["warnings"]
    w = res["warnings"][0]
    assert "column 'delta' (delta, declared rad, scale 1.5)" in w and "steering ratio" in w, w
    assert "declare scale = " in w, w                             # the scale that restores the model's ratio
    text = _validate(observer, log)
    assert text.returncode == 0 and "1 warning(s) below" in text.stdout and "warning: " in text.stdout


@pytest.mark.slow       # runs a compiled extension (the fast lane has no build)
def test_a_speed_25_percent_off_is_a_warning(tmp_path, log):
    """v_x x 1.25 through the column map (wheel speeds with another rolling radius): the identity
    a_y = v_x (dbeta/dt + r) holds with ratio 0.8, inside its refusing band (mounting, bank) but more than
    10 % off: a warning naming the relation and the columns, never silent (it passed every check)."""
    observer = _observer(tmp_path, v_x='{ column = "vx", unit = "m/s", scale = 1.25 }')
    proc = _validate(observer, log, "--json")
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    said = [w for w in res["warnings"] if "more than 10 % off 1" in w]
    assert len(said) == 1 and "column 'vx' (v_x, declared m/s, scale 1.25)" in said[0], res["warnings"]
    ratio = float(re.search(r"holds with ratio ([0-9.]+)", said[0]).group(1))
    assert 0.75 < ratio < 0.85, said[0]                       # 1 / 1.25, with the log's own spread


@pytest.mark.slow       # runs a compiled extension (the fast lane has no build)
def test_a_steering_ratio_slip_in_the_shared_format(tmp_path, log):
    run = S.load(log)
    cols = {c: np.array(getattr(run, c)) for c in S.COLUMNS}
    for c in ("delta", "delta_fl", "delta_fr"):
        cols[c] = 1.5 * cols[c]
    res = logs.run(NAME, str(_write(tmp_path / "slip.csv", cols)))
    assert len(res["warnings"]) == 1 and "column 'delta' (delta, the shared format's unit rad)" in res["warnings"][0]
    assert "steering ratio" in res["warnings"][0]


# --- the checks themselves --------------------------------------------------------------------------

def _checks(input_names=("delta", "y_r", "y_a_y", "v_x"), **units):
    config = observers.get(NAME)
    model = config.load_model()
    cols = {n: L.Column(MAP[n][0], units.get(n, MAP[n][1]), model_unit(model, n)) for n in input_names}
    return L.LogChecks("log.csv", model, load_parameters(config.parameter_path), input_names, cols, 0.01)


def _feed(checks, cols: dict, chunk: int | None = None, **scale):
    n = cols["t"].size
    step = chunk or n
    for i in range(0, n, step):
        part = {k: v[i:i + step] for k, v in cols.items()}
        checks.feed(part["t"], {k: part[MAP[k][0]] * scale.get(k, 1.0) for k in checks.names})
    return checks.finish()


def test_relations_are_derived_from_the_model():
    rel = {r.kind: r for r in _checks().relations}
    assert rel["identity"].what.startswith("y_a_y = v_x*dbeta/dt + v_x*y_r")
    assert rel["identity"].exponents == {"v_x": -1, "y_a_y": 1, "y_r": -1}
    assert rel["steady state"].inputs == ("delta", "v_x", "y_a_y", "y_r")   # a_y through the tyre utilization s
    assert rel["steady state"].exponents["delta"] == -1


def test_the_checks_do_not_depend_on_the_chunking():
    cols = _synthetic()
    whole = _feed(_checks(), cols)
    for chunk in (7, 100, 1001):
        parts = _feed(_checks(), cols, chunk=chunk)
        for a, b in zip(whole["checks"], parts["checks"]):
            assert a["samples"] == b["samples"] and a["verdict"] == b["verdict"]
            assert a["ratio"] == pytest.approx(b["ratio"], rel=1e-9) and a["correlation"] == pytest.approx(
                b["correlation"], rel=1e-9)


def test_a_straight_drive_is_not_judged():
    n = 2000
    rng = np.random.default_rng(1)
    cols = {"t": 0.01 * np.arange(n), "vx": np.full(n, 25.0), "ay": 0.05 * rng.standard_normal(n),
            "yaw_rate": 1e-3 * rng.standard_normal(n), "delta": np.zeros(n)}
    rep = _feed(_checks(), cols)
    assert {c["verdict"] for c in rep["checks"]} == {"not judged"} and rep["warnings"] == []


def test_range_beyond_the_model_box_with_a_unit_that_fits():
    with pytest.raises(DatasetError, match=r"column 'vx' \(v_x, declared m/s\).*beyond 2 x the model's box "
                                           r"\[15, 65\].*looks like km/h"):
        _feed(_checks(), _synthetic(vx0=36.0), v_x=3.6)


@pytest.mark.slow       # 8 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_every_builtin_model_derives_without_error():
    """The derivation is generic: every built-in observer with one ModelDefinition gets its
    relations (or none) without an error, and a known relation where its model has one."""
    seen = {}
    for name in observers.names():
        config = observers.get(name)
        try:
            model = config.load_model()
        except Exception:          # a family whose model is not one ModelDefinition (interconnected)
            continue
        lock = json.loads((ROOT / "generated_c" / name / f"{name}_design.json").read_text())
        seen[name] = {r.kind for r in L.derive(model, load_parameters(config.parameter_path), lock["signals"]["input"])}
    assert seen["lpv_linf_driver_torque"] == {"kinematic", "steady state"}      # d delta/dt = delta_dot; r(delta)
    assert seen["switched_pi_bank_angle"] == {"kinematic", "steady state"}      # d phi/dt = phi_dot; r(delta)
    assert seen["stanford_sideslip_nonlinear_tyre"] == {"identity", "steady state"}
    assert seen["ts_fuzzy_uio"] == set()               # delta unknown: no known input drives a steady state


def _truth_checks(unit: str):
    checks = _checks()
    model = observers.get(NAME).load_model()
    truth = {"beta": L.Column("beta_true", unit, model_unit(model, "beta"), table="data.truth")}
    import dataclasses
    params = dataclasses.replace(checks.params, state_bounds={"beta": (-0.1, 0.1)})    # the box the design certifies
    return L.LogChecks("log.csv", model, params, checks.names, {n: checks.columns[n] for n in checks.names},
                       0.01, truth=truth)


def _feed_truth(checks, cols: dict, scale: float):
    checks.feed(cols["t"], {k: cols[MAP[k][0]] for k in checks.names})
    checks.feed_truth({"beta": cols["beta_true"] * scale})
    return checks.finish()


def test_a_reference_column_is_checked_for_its_unit_too():
    """[data.truth] columns get the unit checks of the inputs: a reference in degrees declared in radians
    is an error naming [data.truth]; one in radians declared in mrad (1000 x too small) a warning."""
    cols = _synthetic()
    assert _feed_truth(_truth_checks("rad"), cols, 1.0)["warnings"] == []
    with pytest.raises(DatasetError, match=r"column 'beta_true' \(reference of beta, declared rad\).*beyond 2 x the "
                                           r"model's box .* for beta; it looks like deg.*in \[data.truth\]"):
        _feed_truth(_truth_checks("rad"), cols, 180 / np.pi)
    warnings = _feed_truth(_truth_checks("mrad"), cols, 1e-3)["warnings"]
    assert len(warnings) == 1 and re.search(r"column 'beta_true' \(reference of beta, declared mrad\).* under 1/100 of "
                                            r"the model's box .* for beta; in rad \(x 1000\).*\[data.truth\]", warnings[0])


def test_a_state_whose_derivative_is_a_measured_rate_derives(tmp_path):
    """A roll model: d roll/dt = rollr with roll unmeasured and rollr measured. The steady state of
    rollr replaces roll and rollr by 0, and the equation of roll is then the bare number 0 (before:
    ``AttributeError: 'int' object has no attribute 'has'``, a traceback from ``uiogen validate --data``)."""
    import sympy as sp
    from codegen.model import ModelDefinition, SchedulingSignal
    vlat, yawr, roll, rollr, steer, bank = sp.symbols("vlat yawr roll rollr steer bank")
    spd = sp.Symbol("spd", positive=True)
    M, I_z, I_x, C_f, C_r, K, C = sp.symbols("M I_z I_x C_f C_r K C", positive=True)
    F_f, F_r = C_f * (steer - (vlat + 1.2 * yawr) / spd), C_r * (1.5 * yawr - vlat) / spd
    model = ModelDefinition(
        name="roll_bank", states=(vlat, yawr, roll, rollr), known_inputs=(steer,), unknown_inputs=(bank,),
        dynamics=sp.Matrix([(F_f + F_r) / M - spd * yawr + 9.81 * bank, (1.2 * F_f - 1.5 * F_r) / I_z, rollr,
                            (200 * (F_f + F_r) / M - K * roll - C * rollr) / I_x]),
        outputs=(("yawr", yawr), ("rollr", rollr), ("ay", (F_f + F_r) / M)),
        scheduling=(SchedulingSignal(spd, "m/s"),), parameters=(M, I_z, I_x, C_f, C_r, K, C),
        units={"vlat": "m/s", "yawr": "rad/s", "roll": "rad", "rollr": "rad/s", "steer": "rad", "bank": "rad",
               "ay": "m/s^2", "spd": "m/s"})
    car = tmp_path / "car.toml"
    car.write_text("[parameters]\nM = 1600.0\nI_z = 2600.0\nI_x = 550.0\nC_f = 110000.0\nC_r = 120000.0\n"
                   "K = 80000.0\nC = 5000.0\n\n[scheduling.spd]\nmin = 8.0\nmax = 40.0\nrate_min = -4.0\n"
                   "rate_max = 4.0\n")
    relations = L.derive(model, load_parameters(car), ["steer", "y_yawr", "y_rollr", "y_ay", "spd"])
    assert "identity" in {r.kind for r in relations}              # y_ay = d vlat/dt + spd y_yawr
