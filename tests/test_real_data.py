"""Real vehicle data (shared Stanford log): the compiled observer against the log's sideslip reference
(beta_true = atan2(vy, vx) of the log's own velocities)."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from codegen.validation import run as validate
from codegen.errors import SampleError
from codegen.validation import stanford

from conftest import require_shared

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(autouse=True)
def _shared_log():
    require_shared(stanford.STANFORD_PATH, "shared Stanford log")


def test_stanford_observer_beats_the_linear_kf():
    r = validate.run_data("stanford_sideslip", "stanford")
    ours, kf = r["observer"]["beta"]["rms"], r["baselines"]["linear_kf"]["beta"]["rms"]
    assert r["status_flags"] == 0 and r["samples"] == 27500
    assert 0.6 < kf < 0.75                    # the source repository's KF, reproduced (~0.68 deg)
    assert ours <= 0.55                       # issue target, no per-log tuning
    assert ours <= 0.8 * kf                   # at least 20 % below the KF measured in the same run


def test_observer_without_the_logged_signals_is_refused():
    with pytest.raises(SampleError, match="stanford_sideslip"):
        validate.run_data("lpv_linf_driver_torque", "stanford")


def test_cli_json_format(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "validate", "stanford_sideslip", "--data",
                           "stanford", "--json"], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert set(res) == {"observer", "baselines", "status_flags", "samples", "peaks", "splits"}
    assert res["splits"]["t_split"] == 137.5 and res["splits"]["evaluation"]["samples"] == 13750
    assert set(res["baselines"]) == {"linear_kf", "ekf"}
    assert [round(p["t"]) for p in res["peaks"]] == [110, 170, 207]      # the three large-sideslip peaks
    assert res["samples"] > 20000 and res["status_flags"] >= 0
    for table in (res["observer"], *res["baselines"].values()):
        assert set(table) == {"beta", "vy"}
        assert {"rms", "mae", "max"} <= set(table["beta"])
