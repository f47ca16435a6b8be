"""Real vehicle data (shared Stanford log): the compiled observer against the log's sideslip reference
(beta_true = atan2(vy, vx) of the log's own velocities)."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from codegen.validation import logs
from codegen.errors import SampleError
from codegen.validation import stanford

from conftest import require_shared

pytestmark = pytest.mark.slow          # the compiled observers on the shared log

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())


@pytest.fixture(autouse=True)
def _shared_log():
    require_shared(stanford.STANFORD_PATH, "shared Stanford log")


def test_stanford_observer_beats_the_linear_kf():
    r = logs.run("stanford_sideslip", "stanford")
    ours, kf = r["observer"]["beta"]["rms"], r["baselines"]["linear_kf"]["beta"]["rms"]
    assert r["status_flags"] == 0 and r["samples"] == 27500
    assert 0.6 < kf < 0.75                    # the source repository's KF, reproduced (~0.68 deg)
    assert ours <= 0.55                       # issue target, no per-log tuning
    assert ours <= 0.8 * kf                   # at least 20 % below the KF measured in the same run


def test_observer_without_the_logged_signals_is_refused():
    with pytest.raises(SampleError, match="stanford_sideslip"):
        logs.run("lpv_linf_driver_torque", "stanford")


def test_cli_json_is_the_run_the_library_makes():
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "validate", "stanford_sideslip", "--data",
                           "stanford", "--json"], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert set(res) == {"observer", "baselines", "status_flags", "samples", "peaks", "splits", "warnings",
                        "log_checks", "definitions", "uninformative"}
    assert res["warnings"] == [] and {c["verdict"] for c in res["log_checks"]} == {"ok"}
    assert res["uninformative"] == []           # the sideslip estimate carries information
    # the same numbers as the run made in this process (the CLI formats, it does not compute)
    ref = logs.run("stanford_sideslip", "stanford")
    for key in ("observer", "baselines", "status_flags", "samples", "peaks", "splits"):
        assert res[key] == json.loads(json.dumps(ref[key])), key
    # the split counts the log's own samples on each side of the evaluation start
    log = stanford.load()
    t = log.t - log.t[0]
    split = res["splits"]["t_split"]
    assert split == stanford.EVALUATION_T_START
    assert res["splits"]["evaluation"]["samples"] == int((t >= split).sum()) > 0
    assert res["splits"]["identification"]["samples"] + res["splits"]["evaluation"]["samples"] == res["samples"] == t.size
    assert res["status_flags"] == 0          # no sample of the log leaves the observer's declared boxes
    # each peak window holds a large sideslip of the log, and its error is the largest there
    for pk in res["peaks"]:
        m = np.abs(t - pk["t"]) <= logs.PEAK_HALF_WIDTH
        assert abs(pk["truth_peak_deg"]) > 3.0
        assert pk["truth_peak_deg"] == pytest.approx(np.degrees(log.beta_true[m][np.argmax(np.abs(log.beta_true[m]))]))
        assert pk["observer"] == pytest.approx(np.degrees(np.abs(ref["signals"]["beta"] - log.beta_true)[m].max()))
    for table in (res["observer"], *res["baselines"].values()):
        assert set(table) == {"beta", "vy"}
        assert {"rms", "mae", "max", "truth_rms", "rms_percent"} <= set(table["beta"])
        assert (table["beta"]["unit"], table["beta"]["converted_from"], table["vy"]["unit"]) == ("deg", "rad", "m/s")
    assert res["splits"]["unit"] == "deg"


def test_the_peers_run_on_two_processes_with_the_estimates_of_one(monkeypatch):
    """The shared log's baselines (the source's KF and EKF) and an observer family's peers (the same-tyre EKF
    and UKF) run on two worker processes (:class:`codegen.validation.workers.Workers`): the estimates are
    those of one process, number for number."""
    import dataclasses

    from codegen.project import observer_file as observers
    config = observers.get("stanford_sideslip_nonlinear_tyre")
    full = stanford.load(stanford.STANFORD_PATH)
    run = stanford.StanfordRun(**{f.name: (v[:3000] if isinstance(v, np.ndarray) else v)
                                  for f in dataclasses.fields(full) for v in [getattr(full, f.name)]})
    two = logs._baselines(config, run)
    monkeypatch.setattr("os.cpu_count", lambda: 1)
    one = logs._baselines(config, run)
    assert set(two) == set(one) == {"linear_kf", "ekf", "ekf_nonlinear_tyre", "ukf_nonlinear_tyre"}
    for name in one:
        assert np.array_equal(two[name], one[name]), name
