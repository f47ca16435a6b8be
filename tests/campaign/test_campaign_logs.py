"""Campaigns over recorded runs (issue 41): ``logs = [...]`` in place of ``scenarios``, each log read
through the observer file's ``[data]`` map in any format ``validate --data`` reads, the sensors' bias,
delay and noise dispersed over the recorded signal, the errors scored against the map's references.

The observer is ``stanford_sideslip`` (its committed design and built extension, ``--project`` the
checkout) with a ``[data]`` map, as in test_log_formats; the logs are two slices of the shared Ferrari
log, one a CSV, the other an MDF4 file written by asammdf.
"""
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.csv as pcsv
import pytest

from codegen.campaign import engine, runner
from codegen.campaign import spec as campaign_spec
from codegen.errors import ConfigurationError
from codegen.project import observer_file as observers
from codegen.validation import logs as data_logs
from codegen.validation import stanford as S

from conftest import require_shared

asammdf = pytest.importorskip("asammdf")

pytestmark = pytest.mark.slow          # a compiled extension, Dask

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
NAME = "stanford_sideslip"
ROWS = 3000
UNITS = {"delta": "rad", "yaw_rate": "rad/s", "ay": "m/s^2", "vx": "m/s", "beta_true": "rad"}
MAP = {"delta": "delta", "y_r": "yaw_rate", "y_a_y": "ay", "v_x": "vx"}


def _observer(folder: Path) -> Path:
    import re
    text = (ROOT / "model_defs" / "observers" / f"{NAME}.toml").read_text()
    params = re.search(r'(?m)^parameters = "([^"]+)"', text).group(1)
    (folder / params).write_text((ROOT / "model_defs" / "params" / params).read_text())
    text += '\n[data]\ntime = "t"\n\n[data.inputs]\n'
    text += "".join(f'{k} = {{ column = "{c}", unit = "{UNITS[c]}" }}\n' for k, c in MAP.items())
    text += '\n[data.truth]\nbeta = { column = "beta_true", unit = "rad" }\n'
    path = folder / f"{NAME}.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """Two slices of the shared log (a CSV, an MDF4 file with units), the mapped observer file, and
    ``validate --data``'s result on each."""
    require_shared(S.STANFORD_PATH, "shared Stanford log")
    folder = tmp_path_factory.mktemp("campaign_logs")
    table = pcsv.read_csv(S.STANFORD_PATH)
    pcsv.write_csv(table.slice(0, ROWS), folder / "first.csv")
    second = table.slice(ROWS, ROWS)
    mdf = asammdf.MDF(version="4.10")
    t = second.column("t").to_numpy()
    for c, u in UNITS.items():
        mdf.append([asammdf.Signal(second.column(c).to_numpy().astype(float), t, name=c, unit=u)])
    mdf.save(folder / "second.mf4", overwrite=True)
    mdf.close()
    observer = _observer(folder)
    config = observers.get(str(observer), project=ROOT)
    single = {log: data_logs.run(config, str(folder / log)) for log in ("first.csv", "second.mf4")}
    return {"folder": folder, "observer": observer, "validate": single}


def _spec(folder: Path, body: str, name: str = "fleet.toml"):
    path = folder / name
    path.write_text(f'observer = "{NAME}.toml"\n' + body)
    return path


def test_each_log_scores_what_validate_data_gives(logs):
    """Without a dispersion a run is the log as recorded: its RMS and largest error of beta are
    ``validate --data``'s on that log (the same step, the same settle time; sums in another order)."""
    path = _spec(logs["folder"], 'logs = ["first.csv", "second.mf4"]\nruns = 2\n')
    spec = campaign_spec.load(path, project=ROOT)
    assert spec.logs == ("first.csv", "second.mf4") and spec.scenarios == ()
    for k, log in enumerate(spec.logs):
        row = runner.run_one(spec, k)
        ref = logs["validate"][log]["observer"]["beta"]
        assert row["log"] == log and row["status"] == "ok", row
        assert row["rms.beta"] == pytest.approx(ref["rms"], rel=1e-9)
        assert row["max.beta"] == pytest.approx(ref["max"], rel=1e-12)
        assert 0.05 < row["rms.beta"] < 2.0          # degrees: a real sideslip error, not 0 or radians


def test_dispersed_sensors_on_dask_rerun_bit_for_bit(logs, tmp_path):
    """Four runs over two logs on a local Dask cluster: the runs of one log differ by their drawn yaw-rate
    bias and delay; every row re-runs by index in this process to the same numbers; the worst run's trace
    and the summary name the logs."""
    path = _spec(logs["folder"], 'logs = ["first.csv", "second.mf4"]\nruns = 4\nseed = 11\nworst = 1\n'
                 '[sensors.r]\nbias = { dist = "uniform", low = -0.01, high = 0.01 }\n'
                 'delay = { dist = "uniform", low = 0.0, high = 0.05 }\nnoise = 0.002\n', name="dispersed.toml")
    spec = campaign_spec.load(path, project=ROOT)
    summary = engine.run(spec, tmp_path, workers=2)
    assert summary["runs"] == 4 and summary["runs_ok"] == 4 and summary["logs"] == ["first.csv", "second.mf4"]
    rows = engine.read_rows(tmp_path / "runs.csv")
    assert [r["log"] for r in rows] == ["first.csv", "second.mf4"] * 2
    for k in range(4):
        again = runner.run_one(spec, k)
        assert again.keys() == rows[k].keys() and math.isnan(again["ratio"]) and math.isnan(rows[k]["ratio"])
        assert {c: v for c, v in again.items() if c != "ratio"} == {c: v for c, v in rows[k].items() if c != "ratio"}
    assert rows[0]["sensor.r.bias"] != rows[2]["sensor.r.bias"] and rows[0]["rms.beta"] != rows[2]["rms.beta"]
    recorded = logs["validate"]["first.csv"]["observer"]["beta"]["rms"]
    assert all(r["rms.beta"] != recorded for r in rows)          # the dispersion reached the step
    trace = np.genfromtxt(summary["files"]["traces"][0], delimiter=",", names=True)
    assert trace["t"][0] == 0.0 and set(trace.dtype.names) == {"t", "beta_truth", "beta_estimate"}
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert saved["logs"] == ["first.csv", "second.mf4"] and saved["errors"] == {}


def test_a_log_refused_by_its_checks_is_a_run_without_result(logs, tmp_path):
    """A log whose time stops for a second (a gap) fails ``validate --data``'s time check: its runs have
    no result (status ``error``, the typed line kept), the other log's runs are scored, the command exits
    1 and says which."""
    folder = logs["folder"]
    table = pcsv.read_csv(S.STANFORD_PATH).slice(0, ROWS)
    cols = {c: table.column(c).to_numpy().copy() for c in table.column_names}
    cols["t"][1500:] += 1.0
    import pyarrow as pa
    pcsv.write_csv(pa.table(cols), folder / "gap.csv")
    path = _spec(folder, 'logs = ["first.csv", "gap.csv"]\nruns = 2\n', name="gap.toml")
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "campaign", str(path), "--workers", "1",
                           "--project", str(ROOT), "--out", str(tmp_path / "out")], capture_output=True, text=True,
                          cwd=ROOT)
    assert proc.returncode == 1, (proc.stdout, proc.stderr)
    assert "of first.csv, gap.csv" in proc.stdout and "run 1: DatasetError" in proc.stdout, proc.stdout
    assert "gap.csv" in proc.stdout.split("run 1: DatasetError", 1)[1]
    rows = engine.read_rows(tmp_path / "out" / "runs.csv")
    assert rows[0]["status"] == "ok" and rows[1]["status"] == "error" and rows[1]["log"] == "gap.csv"
    assert "1 of 2 runs produced no result (error: 1)" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr                 # said in the row, not raised through Dask's log
    again = subprocess.run([sys.executable, "-m", "codegen.cli", "campaign", str(path), "--only", "1", "--project",
                            str(ROOT)], capture_output=True, text=True, cwd=ROOT)
    assert again.returncode == 1 and "DatasetError" in again.stdout and "gap.csv" in again.stdout, again


@pytest.mark.parametrize("body, key", [
    ('logs = ["first.csv"]\nscenarios = ["excitation"]\nruns = 2\n', "scenarios"),
    ('runs = 2\n', "scenarios"),
    ('logs = []\nruns = 2\n', "logs"),
    ('logs = ["nowhere.mf4"]\nruns = 2\n', "logs[0]"),
    ('logs = ["first.csv", "first.csv"]\nruns = 2\n', "logs"),
    ('logs = ["first.csv"]\nruns = 2\n[parameters]\nM = 1.0\n', "parameters"),
    ('logs = ["first.csv"]\nruns = 2\nscenario_seed = "per_run"\n', "scenario_seed"),
    ('logs = ["first.csv"]\nruns = 2\n[sensors.a_x]\nbias = 0.1\n', "a_x"),
    ('logs = ["first.csv"]\nruns = 2\n[sensors.r]\nnoise = -0.1\n', "noise"),
    ('logs = ["first.csv"]\nruns = 2\nrank_by = "r"\n', "rank_by"),
    ('logs = ["first.csv"]\nruns = 2\n[sensors.r]\nnoise = { dist = "uniform", low = 0.5, high = 2.0, relative = true }\n',
     "relative"),
])
def test_campaign_over_logs_mistakes_are_typed(logs, body, key):
    path = _spec(logs["folder"], body, name="wrong.toml")
    with pytest.raises(ConfigurationError) as err:
        campaign_spec.load(path, project=ROOT)
    assert err.value.key == key and str(path) in str(err.value), str(err.value)


def test_an_observer_without_a_data_map_is_named(logs, tmp_path):
    path = tmp_path / "builtin.toml"
    path.write_text(f'observer = "{NAME}"\nlogs = ["{logs["folder"] / "first.csv"}"]\nruns = 1\n')
    with pytest.raises(ConfigurationError, match=r"no \[data\] table") as err:
        campaign_spec.load(path)
    assert err.value.key == "logs"


def test_duration_truncates_each_log(logs):
    """``duration`` scores each log's first seconds: the row of a 12 s truncation is the full run's statistics
    over those samples (the trace ends there)."""
    spec = campaign_spec.load(_spec(logs["folder"], 'logs = ["first.csv"]\nruns = 1\nduration = 12.0\n',
                                    name="short.toml"), project=ROOT)
    row, trace = runner.run_one(spec, 0, traces=True)
    assert trace["t"][-1] == pytest.approx(12.0) and row["status"] == "ok"
    err = (trace["beta_estimate"] - trace["beta_truth"])[trace["t"] >= 2.0] * 180 / math.pi
    assert row["rms.beta"] == pytest.approx(math.sqrt(np.mean(err ** 2)), rel=1e-12)
    full = runner.run_one(campaign_spec.load(_spec(logs["folder"], 'logs = ["first.csv"]\nruns = 1\n',
                                                   name="whole.toml"), project=ROOT), 0)
    assert row["rms.beta"] != full["rms.beta"]


def test_the_memory_of_a_log_campaign_is_its_stream(logs):
    """A log's run is streamed: its estimate is the stream's peak and a decimated trace, whatever the
    log's length (no run is held whole)."""
    from codegen.campaign import memory
    spec = campaign_spec.load(_spec(logs["folder"], 'logs = ["first.csv"]\nruns = 3\n', name="mem.toml"),
                              project=ROOT)
    s = memory.sizes(spec)
    assert s.streamed and s.errors == 1
    est = memory.estimate(spec, 2)
    assert est.worker == memory.PROCESS_BYTES + memory.LOG_RUN_BYTES + 8 * 3 * s.samples
    assert math.isfinite(est.total) and est.total < 4 * memory.GiB
