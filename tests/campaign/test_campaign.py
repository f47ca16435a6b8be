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
from conftest import HANG_GUARD

pytestmark = pytest.mark.slow          # compiled plants, Dask

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
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
    # a delay not shorter than the run (1e9 s was accepted: the observer saw the first sample only)
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[sensors.r]\ndelay = 1e9\n',
     "delay"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\nduration = 5.0\n'
     '[sensors.r]\ndelay = { dist = "uniform", low = 0.0, high = 5.0 }\n', "high"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_speed"]\nruns = 2\n', "scenarios[0]"),
    # a family without a plant of the library's scenarios: its campaigns run the excitation scenario
    ('observer = "ts_fuzzy_uio"\nscenarios = ["track_varying_speed"]\nruns = 2\n', "scenarios"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 0\n', "runs"),
    # every bad value refused before any run or file (issue 25): a non-finite sensor noise, a run
    # shorter than the settle time, physically impossible dispersions of the plant's parameters
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[sensors.r]\nnoise = inf\n',
     "noise"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[sensors.r]\nbias = nan\n',
     "bias"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\nduration = 1e-9\n',
     "duration"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[parameters]\nM = 0\n', "M"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[parameters]\n'
     'M = { dist = "uniform", low = -0.1, high = 1.1, relative = true }\n', "low"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[parameters]\n'
     'I_z = { dist = "normal", mean = 1.0, std = 0.1, relative = true }\n', "dist"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[parameters]\n'
     'mu = { dist = "uniform", low = 0.0, high = 1.0 }\n', "low"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[parameters]\nE_pac = 1.5\n',
     "E_pac"),
    ('observer = "switched_pi_bank_angle"\nscenarios = ["banked_road_braking"]\nruns = 2\n[parameters]\n'
     'm = { dist = "uniform", low = 0.0, high = 1.1, relative = true }\n', "low"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\n[sensors.r]\n'
     'noise = { dist = "uniform", low = -1.0, high = 1.0, relative = true }\n', "low"),
    ('observer = "lpv_linf_driver_torque"\nscenarios = ["track_varying_speed"]\nruns = 2\nrun_timeout = 0\n',
     "run_timeout"),
])
def test_campaign_file_mistakes_are_typed_errors_naming_file_and_key(tmp_path, text, key):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigurationError) as exc:
        campaign_spec.load(path)
    assert exc.value.key == key and str(path) in str(exc.value)
    out = tmp_path / "out"
    res = cli("campaign", str(path), "--out", str(out))
    assert res.returncode == 2 and "Traceback" not in res.stderr and key in res.stderr
    assert not out.exists()                                      # before any run or file


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
        _wait_for_workers(address, sched, worker)
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
            p.wait(timeout=HANG_GUARD)


# --- campaigns that keep what they did (issue 25) --------------------------------------------------------

def test_only_k_outside_the_campaign_is_refused():
    res = cli("campaign", str(LINF_SPEC), "--only", "200")               # runs = 200: indices 0..199
    assert res.returncode == 2 and "Traceback" not in res.stderr and "--only 200" in res.stderr, res.stderr
    res = cli("campaign", str(LINF_SPEC), "--runs", "5", "--only", "5")
    assert res.returncode == 2 and "0 to 4" in res.stderr, res.stderr


def test_a_flagged_run_is_counted_never_ok():
    """A sensor that gives no finite sample (bypassing the file's check, which refuses noise = inf):
    every sample flagged NONFINITE_INPUT; the run is "flagged", left out of the distributions."""
    import dataclasses
    from codegen.campaign import report
    from codegen.campaign.spec import Dist
    spec = dataclasses.replace(campaign_spec.load(LINF_SPEC).with_runs(2), duration=10.0,
                               sensors=(("r", (("noise", Dist("constant", float("inf"))),)),))
    rows = [runner.run_one(spec, k) for k in range(2)]
    assert [r["status"] for r in rows] == ["flagged", "flagged"] and rows[0]["flagged_fraction"] == 1.0
    summary = report.summarize(spec, rows, wall_s=1.0, workers=1, scheduler="test")
    assert summary["runs_ok"] == 0 and summary["runs_failed"] == {"flagged": 2}
    line = report.format_summary(summary).splitlines()[0]
    assert "(0 ok; not ok: 2 flagged)" in line, line


def _spec_file(tmp_path, base: Path = LINF_SPEC, **keys) -> Path:
    """A copy of a campaign file with top-level keys set (before its first table)."""
    lines = base.read_text().splitlines()
    first_table = next(i for i, line in enumerate(lines) if line.startswith("["))
    head = [line for line in lines[:first_table] if line.split("=")[0].strip() not in keys]
    head += [f"{k} = {v!r}" if not isinstance(v, str) else f'{k} = "{v}"' for k, v in keys.items()]
    path = tmp_path / base.name
    path.write_text("\n".join(head + lines[first_table:]) + "\n")
    return path


def _same(a: dict, b: dict) -> bool:
    """Rows equal bit for bit, NaN (a spun plant's metrics) equal to NaN."""
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def _journal_rows(path: Path) -> list:
    lines = path.read_text().splitlines() if path.exists() else []
    return [json.loads(line) for line in lines[1:] if "run" in json.loads(line)]


def _wait_for_rows(journal: Path, n: int, proc) -> None:
    """Until ``n`` runs are in the journal: an event, never a time a loaded machine could overrun; the
    campaign's process ending first fails the test."""
    import time
    while len(_journal_rows(journal)) < n:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.2)


def _wait_for_workers(address: str, *procs) -> None:
    """Until the cluster at ``address`` has a worker (an event); a process of it that ended fails the test."""
    import time
    from dask.distributed import Client
    while True:
        try:
            with Client(address, timeout=5) as c:
                if c.scheduler_info()["workers"]:
                    return
        except OSError:
            pass
        assert all(p.poll() is None for p in procs), "a process of the local distributed cluster ended"
        time.sleep(0.5)


def test_a_killed_campaign_keeps_its_runs_and_resumes(tmp_path):
    """Kill the whole campaign (its process group: the client and the local cluster) after a few
    runs: the runs it finished are in runs.jsonl; without --resume the folder is refused, with it
    the campaign finishes, running only the rest; every row equals its re-run by index."""
    import os
    import signal
    spec_path = _spec_file(tmp_path, runs=60, chunk=1, duration=8.0)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "codegen.cli", "campaign", str(spec_path), "--workers", "1", "--out", str(out)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    journal = out / engine.JOURNAL
    try:
        _wait_for_rows(journal, 3, proc)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    kept = _journal_rows(journal)
    assert 3 <= len(kept) < 60 and not (out / "summary.json").exists()
    res = cli("campaign", str(spec_path), "--workers", "1", "--out", str(out))
    assert res.returncode == 2 and "--resume" in res.stderr and "interrupted" in res.stderr, res.stderr
    res = cli("campaign", str(spec_path), "--workers", "1", "--out", str(out), "--resume", "--json")
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["runs"] == 60 and summary["resumed_runs"] == len(kept)
    spec = campaign_spec.load(spec_path)
    rows = engine.read_rows(out / "runs.csv")
    assert [r["run"] for r in rows] == list(range(60))
    assert all(_same(rows[r["run"]], r) for r in kept)                                # kept as written
    for k in (kept[0]["run"], 59):
        assert _same(rows[k], runner.run_one(spec, k))
    # another campaign file (or design) is never mixed in
    (tmp_path / "other").mkdir()
    other = _spec_file(tmp_path / "other", runs=60, chunk=1, duration=8.0, seed=7)
    res = cli("campaign", str(other), "--workers", "1", "--out", str(out), "--resume")
    assert res.returncode == 2 and "another campaign" in res.stderr and "spec_sha256" in res.stderr, res.stderr


def test_with_its_only_worker_killed_the_campaign_stops_and_keeps_its_runs(tmp_path):
    """A scheduler and ONE worker (no nanny to restart it), the worker killed mid-campaign: the
    campaign does not wait forever; it stops after run_timeout with a typed error naming --resume,
    keeping the runs it finished; a new worker and --resume finish it."""
    import os
    import signal
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    worker_cmd = [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1", "--no-nanny",
                  "--no-dashboard"]
    sched = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                              "--port", str(port), "--no-dashboard"],
                             cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = subprocess.Popen(worker_cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    spec_path = _spec_file(tmp_path, runs=200, chunk=1, duration=8.0, run_timeout=30.0)
    out = tmp_path / "out"
    campaign = [sys.executable, "-m", "codegen.cli", "campaign", str(spec_path), "--scheduler", address,
                "--out", str(out)]
    try:
        _wait_for_workers(address, sched, worker)
        proc = subprocess.Popen(campaign, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        _wait_for_rows(out / engine.JOURNAL, 2, proc)
        worker.send_signal(signal.SIGKILL)
        worker.wait()
        # it stops by itself (after run_timeout = 30 s without a result): ending at all, with the typed
        # error, is the proof; the bound below only keeps a hung campaign from hanging the suite, 20 x
        # the run timeout, which no slow machine reaches (issue 39: no wall-clock limit a test can hit)
        stdout, stderr = proc.communicate(timeout=HANG_GUARD)
        assert proc.returncode == 2 and "Traceback" not in stderr, stderr
        assert "CampaignError" in stderr and "--resume" in stderr and "did not finish" in stderr, stderr
        kept = _journal_rows(out / engine.JOURNAL)
        assert 2 <= len(kept) < 200
        worker = subprocess.Popen(worker_cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL)
        _wait_for_workers(address, sched, worker)
        res = subprocess.run([*campaign, "--resume", "--json"], cwd=ROOT, capture_output=True, text=True,
                             timeout=HANG_GUARD)
        assert res.returncode == 0, res.stderr
        assert json.loads(res.stdout)["resumed_runs"] == len(kept)
        rows = engine.read_rows(out / "runs.csv")
        assert [r["run"] for r in rows] == list(range(200))
        assert _same(rows[199], runner.run_one(campaign_spec.load(spec_path), 199))
    finally:
        for p in (worker, sched):
            p.kill()
            p.wait(timeout=HANG_GUARD)


def test_a_run_that_raises_is_reported_and_the_others_kept(tmp_path):
    """The safety net beneath the file's checks: a run that raises on its worker (here a duration
    below the settle time, which the file refuses) is re-run alone, recorded as "error" with the
    exception, and counted; the campaign does not die with a worker traceback."""
    import dataclasses
    spec = dataclasses.replace(campaign_spec.load(LINF_SPEC).with_runs(4), duration=1.0, chunk=2, worst=0)
    summary = engine.run(spec, tmp_path, workers=1)
    assert summary["runs_ok"] == 0 and summary["runs_failed"] == {"error": 4}
    rows = engine.read_rows(tmp_path / "runs.csv")
    assert all(r["status"] == "error" and "ZeroDivisionError" in r["error"] for r in rows)


def test_the_journal_cuts_a_torn_last_line_and_refuses_damage(tmp_path):
    """A process killed while appending leaves a line without its newline: cut on --resume, the
    rows before it kept. A damaged line elsewhere, or another campaign's header, is refused."""
    from codegen.errors import CampaignError
    header = {"format": engine.JOURNAL_FORMAT, "observer": "x", "design": "d", "spec_sha256": "s"}
    path = tmp_path / engine.JOURNAL
    rows = [{"run": 0, "status": "ok", "rms.beta": 0.1}, {"run": 2, "status": "plant_spun", "rms.beta": float("nan")}]
    good = "".join(json.dumps(e) + "\n" for e in [header, *rows])
    path.write_text(good + '{"run": 1, "sta')
    with pytest.raises(CampaignError, match="interrupted"):          # not overwritten without --resume
        engine.Journal(path, header, resume=False)
    journal = engine.Journal(path, header, resume=True)
    journal.close()
    assert sorted(journal.rows) == [0, 2] and path.read_text() == good
    with pytest.raises(CampaignError, match="another campaign"):
        engine.Journal(path, {**header, "design": "e"}, resume=True)
    path.write_text(good.replace('"run": 0', '"run: 0', 1))
    with pytest.raises(CampaignError, match="line 2"):
        engine.Journal(path, header, resume=True)


def test_resume_runs_lost_runs_again_and_a_campaign_with_runs_without_result_exits_nonzero(tmp_path):
    """A finished campaign whose journal holds a worker_lost run and an error run: --resume runs the lost
    one again (its row then equals its run by index), keeps the error, writes the reports and exits 1
    naming both; with every run kept it would exit 0."""
    spec_path = _spec_file(tmp_path, runs=4, chunk=1, duration=6.0)
    out = tmp_path / "out"
    res = cli("campaign", str(spec_path), "--workers", "1", "--out", str(out), "--json")
    assert res.returncode == 0, res.stderr
    journal = out / engine.JOURNAL
    lines = [json.loads(line) for line in journal.read_text().splitlines()]
    original = {e["run"]: dict(e) for e in lines if "run" in e}
    for e in lines:
        if e.get("run") == 1:
            e.clear()
            e.update({"run": 1, "scenario": original[1]["scenario"], "status": "worker_lost", "error": "killed"})
        elif e.get("run") == 2:
            e.clear()
            e.update({"run": 2, "scenario": original[2]["scenario"], "status": "error", "error": "raised"})
    journal.write_text("".join(json.dumps(e) + "\n" for e in lines))
    res = cli("campaign", str(spec_path), "--workers", "1", "--out", str(out), "--resume", "--json")
    assert res.returncode == 1, res.stderr
    assert "1 of 4 runs produced no result (error: 1)" in res.stderr and "Traceback" not in res.stderr
    summary = json.loads(res.stdout)
    assert summary["resumed_runs"] == 3 and summary["runs_failed"].get("error") == 1
    assert "worker_lost" not in summary["runs_failed"]
    rows = engine.read_rows(out / "runs.csv")
    assert _same(rows[1], original[1]) and rows[2]["status"] == "error"
