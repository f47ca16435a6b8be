"""uiogen campaign: the compiled plants against the Python reference plants, a 20-run campaign on a
local Dask cluster whose rows re-run bit for bit by index, and the campaign file's typed errors."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from codegen.project import observer_file as observers
from codegen.validation import simulate
from codegen.campaign import engine, runner
from codegen.campaign import spec as campaign_spec
from codegen.campaign.plants import CompiledPlant
from codegen.errors import ConfigurationError
from codegen.model import load_parameters
from codegen.validation import scenarios
from codegen.validation.common import scenario_for, truth_plant

pytestmark = pytest.mark.slow          # compiled plants, Dask

ROOT = Path(__file__).resolve().parent.parent
LINF_SPEC = ROOT / "docs" / "campaigns" / "lpv_linf_driver_torque.toml"
BANK_SPEC = ROOT / "docs" / "campaigns" / "switched_pi_bank_angle.toml"


def cli(*args):
    return subprocess.run([sys.executable, "-m", "codegen.cli", *args], capture_output=True, text=True, cwd=ROOT)


def _close(out, ref, keys):
    for k in keys:
        scale = float(np.max(np.abs(ref[k])))
        assert np.max(np.abs(out[k] - ref[k])) <= 1e-10 * scale + 1e-14, k


def test_compiled_steering_torque_plant_matches_the_python_nominal_plant():
    from codegen.families.linf_uio.build import representation
    cfg = observers.get("lpv_linf_driver_torque")
    scn = scenario_for(cfg, "track_varying_speed", 20.0)
    lpv = representation(cfg)[0]
    ref = simulate.nominal_plant(cfg, lpv, scn, truth_plant(cfg, lpv.parameters))
    out = CompiledPlant(cfg, scn.t.size).simulate(scn)
    _close(out, ref, ("beta", "r", "delta", "delta_dot", "T_d", "a_y", "v_x", "T_a"))


def test_compiled_banked_road_plant_matches_the_python_banked_plant():
    from codegen.families.switched_pi.validation import banked_plant
    from codegen.validation.common import truncate
    cfg = observers.get("switched_pi_bank_angle")
    scn = truncate(scenarios.make("banked_road_braking", sample_rate=1 / cfg.sample_time), 25.0)
    ref = banked_plant(cfg, load_parameters(cfg.parameter_path), scn)
    out = CompiledPlant(cfg, scn.t.size).simulate(scn)
    _close(out, ref, ("v_y", "beta", "r", "phi", "phi_dot", "delta", "a_y", "phi_r"))


def test_dispersed_parameters_reach_the_compiled_plant():
    cfg = observers.get("lpv_linf_driver_torque")
    scn = scenario_for(cfg, "track_varying_speed", 10.0)
    plant = CompiledPlant(cfg, scn.t.size)
    nominal, heavy = plant.simulate(scn), plant.simulate(scn, {"M": 1.3 * plant.spec.params["M"]})
    assert not np.array_equal(nominal["beta"], heavy["beta"])
    assert np.array_equal(nominal["beta"], plant.simulate(scn, {})["beta"])


def test_20_run_campaign_on_a_local_dask_cluster_rows_rerun_bit_for_bit(tmp_path):
    spec = campaign_spec.load(LINF_SPEC).with_runs(20)
    summary = engine.run(spec, tmp_path, workers=2)
    assert summary["runs"] == 20 and summary["workers"] == 2
    rows = engine.read_rows(tmp_path / "runs.csv")
    assert [r["run"] for r in rows] == list(range(20))
    # each row, re-run alone in this process from (spec, index), equals the worker's row exactly
    for k in (0, 7, 19):
        again = runner.run_one(spec, k)
        assert again == rows[k]
    saved = json.loads((tmp_path / "summary.json").read_text())
    from codegen.design import lock as design_lock
    committed = json.loads(design_lock.path(observers.get("lpv_linf_driver_torque")).read_text())["gamma"]
    assert saved["runs"] == 20 and saved["certificate"]["gamma"] == committed      # the certified gamma
    for p in saved["files"]["plots"]:
        assert Path(p).is_file()
    assert len(saved["files"]["traces"]) == spec.worst


def test_only_k_prints_the_row_of_run_k():
    spec = campaign_spec.load(BANK_SPEC)
    res = cli("campaign", str(BANK_SPEC), "--only", "3", "--json")
    assert res.returncode == 0, res.stderr
    row = json.loads(res.stdout)
    assert row == runner.run_one(spec, 3)
    assert row["run"] == 3 and row["status"] == "ok" and 0.0 <= row["clamped_fraction"] <= 1.0


def test_draws_depend_on_seed_and_index_only():
    spec = campaign_spec.load(LINF_SPEC)
    a, b = runner.draw(spec, 5)["values"], runner.draw(spec.with_runs(10_000), 5)["values"]
    assert a == b
    assert a != runner.draw(spec, 6)["values"]


@pytest.mark.parametrize("text, key", [
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[parameters]\nmass = 1.0\n',
     "mass"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[parameters]\n'
     'M = { dist = "gauss", mean = 1.0, std = 0.1 }\n', "dist"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[parameters]\n'
     'M = { dist = "uniform", low = 1.0 }\n', "high"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[sensors.a_x]\nbias = 0.1\n',
     "a_x"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[sensors.r]\ndelay = -0.01\n',
     "delay"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_speed"]\nruns = 2\n', "scenarios[0]"),
    # a family without a plant of the library's scenarios: its campaigns run the excitation scenario
    ('observer = "ts_fuzzy_uio"\nscenarios = ["track_varying_speed"]\nruns = 2\n', "scenarios"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 0\n', "runs"),
])
def test_campaign_file_mistakes_are_typed_errors_naming_file_and_key(tmp_path, text, key):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigurationError) as exc:
        campaign_spec.load(path)
    assert exc.value.key == key and str(path) in str(exc.value)
    res = cli("campaign", str(path))
    assert res.returncode == 2 and "Traceback" not in res.stderr and key in res.stderr


def test_an_existing_distributed_cluster_by_address(tmp_path):
    """--scheduler ADDRESS: a scheduler and a worker started as their own processes (`dask scheduler`,
    `dask worker`, TCP on localhost), the same code path a remote cluster takes; rows equal the
    in-process re-runs bit for bit."""
    import os
    import socket
    import time
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    sched = subprocess.Popen([*dask, "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                             cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "1",
                               "--nthreads", "1", "--no-dashboard"],
                              cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        from dask.distributed import Client
        deadline = time.time() + 60
        while True:
            try:
                with Client(address, timeout=5) as c:
                    if c.scheduler_info()["workers"]:
                        break
            except OSError:
                pass
            assert time.time() < deadline, "the local distributed cluster did not start"
            time.sleep(0.5)
        out = tmp_path / "remote"
        res = cli("campaign", str(LINF_SPEC), "--runs", "4", "--scheduler", address, "--out", str(out), "--json")
        assert res.returncode == 0, res.stderr
        summary = json.loads(res.stdout)
        assert summary["runs"] == 4 and summary["scheduler"] == address
        spec = campaign_spec.load(LINF_SPEC).with_runs(4)
        rows = engine.read_rows(out / "runs.csv")
        assert rows == [runner.run_one(spec, k) for k in range(4)]
    finally:
        for p in (worker, sched):
            p.terminate()
        for p in (worker, sched):
            p.wait(timeout=30)
