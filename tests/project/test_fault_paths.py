"""Faults on user paths that were tracebacks, refusals or silent losses (fault-injection probe B),
each one typed line now, and the previous good state kept:

* a file that is not UTF-8 (parameter file, model file, campaign file): the error names the file;
  any other one the CLI meets names what it can;
* Ctrl-C during a command: one line, exit 130; SIGTERM to a campaign: the --resume hint, exit 143;
* a campaign: no journal before it has a cluster, a journal with a header alone is no interrupted
  campaign, one campaign at a time per folder (a lock), a full disk cuts the torn line and says
  what is kept and that --resume continues, ``--out`` an existing file or a file ``build`` in the way
  and an unreachable scheduler are typed errors;
* ``fit --write``'s two files: all old or all new (a record of the renames, completed by the next
  reader), their permission modes kept;
* ``generate`` on a read-only project with nothing to write: "unchanged", exit 0;
* ``validate --plot NAME`` without a suffix names the file matplotlib writes (NAME.png).
"""
import errno
import json
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from codegen import cli
from codegen.campaign import engine
from codegen.campaign import spec as campaign_spec
from codegen.errors import CampaignError, ConfigurationError, ModelDefinitionError, OutputError
from codegen.project import observer_file as observers
from codegen.project import outputs
from conftest import HANG_GUARD

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
BAD_BYTES = b"\n# \xff\xfe\n"
CAMPAIGN = """observer = "obs1.toml"
scenarios = ["excitation"]
scenario_seed = "per_run"
runs = {runs}
seed = 7
duration = 6.0
chunk = 1
[parameters]
M = {{ dist = "uniform", low = 0.95, high = 1.05, relative = true }}
"""


def _cli(*args, cwd=ROOT, timeout=HANG_GUARD, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "codegen.cli", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=timeout, env=env)


def _env() -> dict:
    return dict(os.environ, PYTHONPATH=str(ROOT))


def _one_line(proc, rc: int = 2) -> str:
    assert proc.returncode == rc, (proc.stdout[-500:], proc.stderr[-2000:])
    err = proc.stderr.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


@pytest.fixture
def project(tmp_path) -> Path:
    """A starter project (``uiogen new``): obs1.toml, model.py, parameters.toml."""
    proc = _cli("new", str(tmp_path / "p"), "--family", "linf_uio", "--name", "obs1")
    assert proc.returncode == 0, proc.stderr
    return tmp_path / "p"


# --- files that are not UTF-8 ------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["parameters.toml", "model.py"])
@pytest.mark.parametrize("verb", ["design", "validate", "generate"])
def test_a_file_that_is_not_utf8_is_one_line_naming_it(project, name, verb):
    with open(project / name, "ab") as fh:
        fh.write(BAD_BYTES)
    extra = ["--scenario", "excitation"] if verb == "validate" else []
    proc = _cli(verb, str(project / "obs1.toml"), *extra)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    if verb == "validate":       # no design yet: that error comes first; one typed line either way
        assert len(proc.stderr.strip().splitlines()) == 1 and "uiogen: error: " in proc.stderr, proc.stderr
    else:
        said = proc.stdout + proc.stderr      # generate: the failure on stdout, the count on stderr
        assert f"{project / name}: not UTF-8 text" in said or f"{project / name} is not UTF-8 text" in said, said


def test_a_campaign_file_that_is_not_utf8_is_a_configuration_error(tmp_path):
    path = tmp_path / "c.toml"
    path.write_bytes(CAMPAIGN.format(runs=2).encode() + BAD_BYTES)
    with pytest.raises(ConfigurationError, match="not UTF-8 text") as e:
        campaign_spec.load(path)
    assert str(path) in str(e.value)
    err = _one_line(_cli("campaign", str(path)))
    assert f"{path}: not UTF-8 text" in err


def test_any_other_undecodable_file_is_one_line_naming_what_it_can(monkeypatch, capsys, tmp_path):
    bad = tmp_path / "x.txt"
    bad.write_bytes(BAD_BYTES)

    def reads(args):
        path = bad
        return path.read_text()
    monkeypatch.setattr(cli, "cmd_list", reads)
    assert cli.main(["list"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"uiogen: error: ConfigurationError: {bad}: not UTF-8 text") and "\n" not in err


# --- interrupts -------------------------------------------------------------------------------------

def test_ctrl_c_is_one_line_and_exit_130(monkeypatch, capsys):
    def interrupted(args):
        raise KeyboardInterrupt
    monkeypatch.setattr(cli, "cmd_generate", interrupted)
    assert cli.main(["generate"]) == 130
    err = capsys.readouterr().err.strip()
    assert err == "uiogen: interrupted: uiogen generate stopped before it finished (the previous state is kept)"


def test_ctrl_c_during_a_design_is_one_line(project):
    """A real SIGINT (the model's import waits for it): one line, exit 130, no file written."""
    marker = project / "importing"
    model = project / "model.py"
    model.write_text(f"import pathlib, time\npathlib.Path({str(marker)!r}).touch()\ntime.sleep(60)\n"
                     + model.read_text())
    # Ctrl-C as a terminal delivers it: SIGINT at its default disposition in the child (a runner that starts the
    # tests in the background, `cmd &` in a script, has it ignored, and Python then installs no handler)
    proc = subprocess.Popen([sys.executable, "-m", "codegen.cli", "design", str(project / "obs1.toml"), "--update"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    # waits for events (the marker, the exit), never for a time a loaded machine could overrun
    while not marker.exists():
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.1)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate()
    assert proc.returncode == 130 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert "interrupted: uiogen design" in err and "previous state is kept" in err
    assert not (project / "generated_c").exists()


# --- the campaign's folder and journal ------------------------------------------------------------------

HEADER = {"format": engine.JOURNAL_FORMAT, "observer": "x", "design": "d", "spec_sha256": "s"}


def test_the_journal_is_written_only_once_started(tmp_path):
    path = tmp_path / engine.JOURNAL
    journal = engine.Journal(path, HEADER, resume=False)
    assert not path.exists()                  # no cluster yet: nothing that reads as an interrupted campaign
    journal.start()
    journal.close()
    assert path.read_text() == json.dumps(HEADER) + "\n"
    # a header alone (a campaign that never ran a task) is no interrupted campaign
    engine.Journal(path, HEADER, resume=False).close()


def test_resuming_a_finished_campaign_marks_it_finished_once(tmp_path):
    path = tmp_path / engine.JOURNAL
    journal = engine.Journal(path, HEADER, resume=False)
    journal.start()
    journal.append([{"run": 0, "status": "ok"}])
    journal.complete(1)
    journal.close()
    for _ in range(2):               # --resume of a finished campaign re-writes its reports only
        again = engine.Journal(path, HEADER, resume=True)
        assert again.finished and set(again.rows) == {0}
        again.start()
        again.complete(1)
        again.close()
    lines = path.read_text().splitlines()
    assert lines == [json.dumps(HEADER), json.dumps({"run": 0, "status": "ok"}), json.dumps({"complete": 1})]


def test_a_journal_the_disk_refuses_keeps_its_whole_lines(tmp_path, monkeypatch):
    path = tmp_path / engine.JOURNAL
    journal = engine.Journal(path, HEADER, resume=False, source="c.toml")
    journal.start()
    journal.append([{"run": 0, "status": "ok"}])
    before = path.read_bytes()
    real_write = os.write

    def full(fd, data):          # half the line goes in, then the disk is full
        if fd == journal._fd and len(data) > 8:
            real_write(fd, data[:8])
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_write(fd, data)
    monkeypatch.setattr(os, "write", full)
    with pytest.raises(OutputError) as e:
        journal.append([{"run": 1, "status": "ok"}])
    journal.close()
    msg = str(e.value)
    assert str(path) in msg and "ENOSPC" in msg and "1 runs finished before are kept" in msg, msg
    assert f"uiogen campaign c.toml --resume --out {tmp_path}" in msg and "nothing partial" not in msg
    assert path.read_bytes() == before


def test_one_campaign_at_a_time_per_folder(tmp_path):
    with engine.exclusive(tmp_path, "c.toml"):
        with pytest.raises(CampaignError, match=f"another campaign is running into {tmp_path} "
                                                f"\\(pid {os.getpid()}\\)"):
            with engine.exclusive(tmp_path, "c.toml"):
                pass
    with engine.exclusive(tmp_path, "c.toml"):          # released: the next one runs
        pass


def test_a_file_in_the_way_of_an_output_folder(tmp_path):
    """A campaign's --out or an FMU's folder under a file: named (was mkdir's bare 'File exists')."""
    from codegen.project import outputs
    (tmp_path / "build").write_text("")
    with pytest.raises(OutputError, match=f"{tmp_path / 'build'} is a file, not a folder"):
        outputs.make_folder(tmp_path / "build" / "campaigns" / "c")
    with pytest.raises(OutputError, match="is a file, not a folder"):
        outputs.make_folder(tmp_path / "build")
    assert outputs.make_folder(tmp_path / "a" / "b").is_dir()


@pytest.mark.slow       # Dask: a client that waits for a scheduler
def test_an_unreachable_scheduler_is_a_campaign_error():
    import dask
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        with pytest.raises(CampaignError, match="cannot reach the Dask scheduler at tcp://127.0.0.1:1"):
            engine.client_for("tcp://127.0.0.1:1")


@pytest.fixture
def built(project) -> Path:
    for verb in ("generate", "build"):
        proc = _cli(verb, str(project / "obs1.toml"))
        assert proc.returncode == 0, proc.stderr
    return project


@pytest.mark.slow       # a compiled extension and plant, a local Dask cluster
def test_campaign_folder_faults_on_the_command_line(built, tmp_path):
    spec = built / "camp.toml"
    spec.write_text(CAMPAIGN.format(runs=400))
    err = _one_line(_cli("campaign", str(spec), "--out", str(spec)))
    assert f"{spec} is a file, not a folder" in err
    # no cluster: no journal, so the next campaign is not refused
    err = _one_line(_cli("campaign", str(spec), "--scheduler", "tcp://127.0.0.1:1", "--out", str(tmp_path / "o"),
                         env={**_env(), "DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "1s"}))
    assert "cannot reach the Dask scheduler" in err and not (tmp_path / "o" / engine.JOURNAL).exists()
    # a second campaign into the folder of a running one is refused; SIGTERM keeps the runs
    out = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-m", "codegen.cli", "campaign", str(spec), "--workers", "1",
                             "--out", str(out)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    while not (out / engine.JOURNAL).exists() or len((out / engine.JOURNAL).read_text().splitlines()) < 3:
        assert proc.poll() is None, proc.communicate()          # an event, not a time
        time.sleep(0.2)
    err = _one_line(_cli("campaign", str(spec), "--workers", "1", "--out", str(out), "--resume"))
    assert f"another campaign is running into {out} (pid {proc.pid})" in err
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=HANG_GUARD)
    assert proc.returncode == 143 and "Traceback" not in err, err
    assert f"--resume --out {out}` continues" in err


# --- fit --write: two files, one change ---------------------------------------------------------------------

def test_files_written_together_are_all_old_or_all_new(tmp_path, monkeypatch):
    a, b = tmp_path / "params.toml", tmp_path / "obs.toml"
    a.write_text("old a")
    b.write_text("old b")
    os.chmod(a, 0o600)
    real_replace = os.replace
    calls = []

    def killed(src, dst):            # the process dies after the first file's rename
        if str(dst) in (str(a), str(b)):
            if calls:
                raise SystemExit("killed")
            calls.append(dst)
        return real_replace(src, dst)
    monkeypatch.setattr(os, "replace", killed)
    with pytest.raises(SystemExit):
        outputs.write_together({a: "new a", b: "new b"}, b)
    monkeypatch.setattr(os, "replace", real_replace)
    assert outputs.pending_path(b).exists()            # half done, and recorded
    logged = []
    assert len(outputs.finish_pending(b, log=logged.append)) == 1 and "interrupted" in logged[0]
    assert (a.read_text(), b.read_text()) == ("new a", "new b") and not outputs.pending_path(b).exists()
    assert stat.S_IMODE(a.stat().st_mode) == 0o600
    assert sorted(p.name for p in tmp_path.iterdir()) == ["obs.toml", "params.toml"]
    # killed before the record: both old, no temporary left
    monkeypatch.setattr(outputs, "write_atomic", lambda *a: (_ for _ in ()).throw(SystemExit("killed")))
    with pytest.raises(SystemExit):
        outputs.write_together({a: "newer a", b: "newer b"}, b)
    assert (a.read_text(), b.read_text()) == ("new a", "new b")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["obs.toml", "params.toml"]


def test_the_next_reader_completes_an_interrupted_fit_write(project, capsys):
    obs = project / "obs1.toml"
    new = obs.read_text().replace("sample_time", "# fitted\nsample_time", 1)
    tmp = obs.with_name(".obs1.toml.new-1")
    tmp.write_text(new)
    outputs.pending_path(obs).write_text(json.dumps([[str(tmp), str(obs)]]))
    observers.get(str(obs))
    assert obs.read_text() == new and not tmp.exists() and not outputs.pending_path(obs).exists()
    assert "completed an interrupted write" in capsys.readouterr().err


def test_write_atomic_keeps_the_mode(tmp_path):
    path = tmp_path / "f.toml"
    path.write_text("x")
    os.chmod(path, 0o640)
    outputs.write_atomic(path, "y")
    assert stat.S_IMODE(path.stat().st_mode) == 0o640 and path.read_text() == "y"


# --- generate on a read-only project, validate --plot without a suffix -----------------------------------

@pytest.mark.slow       # mounts a tmpfs (root) and generates
def test_generate_on_a_read_only_project_with_nothing_to_write(project, tmp_path):
    if os.geteuid() != 0:
        pytest.skip("a read-only file system needs root (mount)")
    ro = tmp_path / "ro"
    ro.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=8m", "tmpfs", str(ro)], capture_output=True).returncode:
        pytest.skip("no tmpfs mount here")
    try:
        subprocess.run(["cp", "-r", str(project), str(ro / "p")], check=True)
        obs = ro / "p" / "obs1.toml"
        assert _cli("generate", str(obs)).returncode == 0
        (ro / "p" / "generated_c" / ".generate.lock").unlink()
        subprocess.run(["mount", "-o", "remount,ro", str(ro)], check=True)
        proc = _cli("generate", str(obs))
        assert proc.returncode == 0 and "unchanged" in proc.stdout, (proc.stdout, proc.stderr)
        proc = _cli("generate", str(obs), "--force")          # something to write: the typed error as before
        assert "OutputError" in _one_line(proc) and "Read-only file system (EROFS)" in proc.stdout, proc.stdout
    finally:
        subprocess.run(["umount", str(ro)], capture_output=True)


@pytest.mark.slow       # a compiled extension
def test_validate_plot_names_the_file_it_writes(built):
    (built / "build_plots").mkdir()
    proc = _cli("validate", str(built / "obs1.toml"), "--scenario", "excitation", "--duration", "3",
                "--plot", str(built / "build_plots"), cwd=built, env=_env())
    assert proc.returncode == 0, proc.stderr
    assert f"plot: {built / 'build_plots'}.png" in proc.stdout and (built / "build_plots.png").is_file()
