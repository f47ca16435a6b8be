"""Names, files and arrays that were tracebacks, silent losses or undefined behaviour (issue 25,
probe 6), each a typed error or a refusal now:

* an observer name that is not a C identifier (``my obs``, ``1abc``, a C keyword) or longer than 64
  characters: refused before any design (was a CasADi traceback after the whole LMI solve, or at
  ``load``);
* a model file that calls ``sys.exit(0)``: a ModelDefinitionError (``design`` exited 0 having done
  nothing);
* a full or read-only output folder: an OutputError naming the path, no ``*.tmp`` or partial file
  left (was an OSError traceback and a partial file);
* generated folders with the user's umask (were 0700, ``tempfile.mkdtemp``'s mode);
* ``run`` with complex or string arrays: refused (the complex part was dropped, strings parsed);
* a step or run whose output buffer overlaps its input buffer: refused (ts_fuzzy_uio gave
  results off by 1e295); a state that a run() of another thread is using: refused.
"""
import os
import re
import resource
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from codegen.errors import ConfigurationError, SampleError
from codegen.project import observer_file as observers
from python_bindings import load
from conftest import HANG_GUARD

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
# an observer file of one's own names its parameter file by a path (here the built-in file's, absolute)
OBSERVER_FILE = re.sub(r'(?m)^parameters = "([^"]+)"',
                       lambda m: f'parameters = "{ROOT / "model_defs" / "params" / m.group(1)}"',
                       (ROOT / "model_defs" / "observers" / "algebraic_uio_example1.toml").read_text())
DESIGNED = "ts_fuzzy_uio"          # designs in seconds; its lock (10.5 kB) does not fit 8 kB


def _cli(*args, cwd=ROOT, preexec=None, timeout=HANG_GUARD) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "codegen.cli", *args], capture_output=True, text=True, cwd=cwd,
                          preexec_fn=preexec, timeout=timeout)


def _one_line(proc) -> str:
    assert proc.returncode == 2, (proc.stdout[-500:], proc.stderr[-2000:])
    err = proc.stderr.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


# --- observer names ------------------------------------------------------------------------------

NOT_SHAPED = "is not made of ASCII letters, digits and single underscores"


@pytest.mark.parametrize("name, why", [("my obs", NOT_SHAPED), ("1abc", NOT_SHAPED), ("my-obs", NOT_SHAPED),
                                       ("double", "is a C keyword"), ("obs_", NOT_SHAPED), ("my__obs", NOT_SHAPED),
                                       ("_x", NOT_SHAPED), ("_Atomic", NOT_SHAPED), ("class", "is a C++ keyword"),
                                       ("errno", "is a macro"), ("a" * 65, "has 65 characters"),
                                       ("a" * 200, "has 200 characters")])
def test_an_observer_name_that_is_not_a_c_identifier_is_refused_before_any_design(tmp_path, name, why):
    path = tmp_path / f"{name}.toml"
    path.write_text(OBSERVER_FILE)
    with pytest.raises(ConfigurationError, match=re.escape(why)) as e:
        observers.get(str(path))
    assert "rename the file" in str(e.value) and "64 characters" in str(e.value)
    err = _one_line(_cli("design", str(path)))
    assert why in err and "ConfigurationError" in err


def test_names_up_to_the_limit_are_accepted(tmp_path):
    for name in ("a" * 64, "x1", "obs_2", "socket"):
        path = tmp_path / f"{name}.toml"
        path.write_text(OBSERVER_FILE)
        assert observers.get(str(path)).name == name


def test_uiogen_new_refuses_a_bad_name_and_writes_nothing(tmp_path):
    for name in ("my obs", "obs_", "my__obs", "_x", "_Atomic", "NAN"):
        err = _one_line(_cli("new", str(tmp_path / "p"), "--family", "linf_uio", "--name", name))
        assert "an observer name is a C identifier" in err and not (tmp_path / "p").exists()


# --- a model file that exits ----------------------------------------------------------------------

@pytest.mark.parametrize("code", ["0", "3", "None"])
def test_a_model_file_calling_sys_exit_is_an_error(tmp_path, code):
    (tmp_path / "exits.py").write_text(f"import sys\nsys.exit({code})\n")
    (tmp_path / "params.toml").write_text("[parameters]\n")
    (tmp_path / "obs.toml").write_text('family = "linf_uio"\nmodel = "exits.py"\nparameters = "params.toml"\n'
                                       'sample_time = 0.01\npolytope = "sector"\n')
    err = _one_line(_cli("design", str(tmp_path / "obs.toml")))
    assert f"called sys.exit({code})" in err and "ModelDefinitionError" in err


# --- output folders ----------------------------------------------------------------------------------

def _file_size_limit(limit: int):
    def apply():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))     # writes beyond: EFBIG (SIGXFSZ ignored)
    return apply


def _leftovers(folder: Path) -> list:
    return sorted(p.name for p in folder.rglob("*") if ".tmp" in p.name or ".new-" in p.name or ".old-" in p.name)


def _mounted(tmp_path, options: str) -> Path:
    """A tmpfs mounted with ``options`` (root only: skip otherwise)."""
    folder = tmp_path / options.replace(",", "_").replace("=", "")
    folder.mkdir()
    if os.geteuid() != 0:
        pytest.skip("a small or read-only file system needs root (mount)")
    proc = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)], capture_output=True)
    if proc.returncode != 0:
        pytest.skip(f"no tmpfs mount here: {proc.stderr.decode().strip()}")
    return folder


@pytest.fixture
def mounts(tmp_path):
    made = []

    def mount(options):
        made.append(_mounted(tmp_path, options))
        return made[-1]
    yield mount
    for folder in made:
        subprocess.run(["umount", str(folder)], capture_output=True)


def _generate_error(proc, folder: Path) -> None:
    """generate goes on with the other observers: the failure on stdout, one line at the end."""
    assert "GenerationError" in _one_line(proc) and "(OutputError)" in proc.stderr
    assert (f"FAILED: OutputError: cannot write {folder}" in proc.stdout
            or f"FAILED: OutputError: cannot create a folder in {folder}" in proc.stdout), proc.stdout


def test_a_file_size_limit_is_an_output_error_and_leaves_nothing(tmp_path):
    """RLIMIT_FSIZE: any user can make a write fail (EFBIG) as a full disk does."""
    lock = tmp_path / "lock" / "d.json"
    err = _one_line(_cli("design", DESIGNED, "--out", str(lock), preexec=_file_size_limit(2000)))
    assert f"OutputError: cannot write {lock}" in err and "EFBIG" in err, err
    assert _leftovers(lock.parent) == [] and not lock.exists()


@pytest.mark.slow       # 5 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_a_full_output_folder_is_an_output_error_and_leaves_nothing(mounts):
    full = mounts("size=8k")
    err = _one_line(_cli("design", DESIGNED, "--out", str(full / "d.json")))
    assert "OutputError" in err and "No space left on device (ENOSPC)" in err, err
    proc = _cli("generate", DESIGNED, "--out", str(full), "--force")
    _generate_error(proc, full)
    assert _leftovers(full) == [] and not (full / DESIGNED).exists() and not (full / "d.json").exists()


@pytest.mark.slow       # 7 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_a_read_only_output_folder_is_an_output_error(mounts):
    ro = mounts("ro,size=16k")
    err = _one_line(_cli("design", DESIGNED, "--out", str(ro / "d.json")))
    assert "OutputError" in err and "Read-only file system (EROFS)" in err, err
    _generate_error(_cli("generate", DESIGNED, "--out", str(ro), "--force"), ro)
    err = _one_line(_cli("validate", "stanford_sideslip", "--data", "stanford", "--plot", str(ro / "p.png")))
    assert f"OutputError: cannot write {ro / 'p.png'}" in err, err


@pytest.mark.parametrize("mask", [0o022, 0o027])
def test_generated_folders_follow_the_umask(tmp_path, mask):
    out = tmp_path / "out"
    proc = _cli("generate", DESIGNED, "--out", str(out), "--force", preexec=lambda: os.umask(mask))
    assert proc.returncode == 0, proc.stderr
    folder = out / DESIGNED
    assert folder.stat().st_mode & 0o777 == 0o777 & ~mask                      # was 0700
    assert (folder / f"{DESIGNED}.c").stat().st_mode & 0o777 == 0o666 & ~mask


# --- arrays the compiled step is given --------------------------------------------------------------

@pytest.fixture(scope="module")
def ts():
    return load("ts_fuzzy_uio")


@pytest.mark.slow       # runs a compiled extension (the fast lane has no build)
@pytest.mark.parametrize("bad", ["complex", "string", "bool", "object"])
def test_run_refuses_arrays_that_are_not_real_numbers(ts, bad):
    rows = np.tile([20.0, 0.01], (10, 1))
    arr = {"complex": rows + 1e-3j, "string": rows.astype(str), "bool": rows > 1,
           "object": rows.astype(object)}[bad]
    with pytest.raises(SampleError, match="must be real numbers"):
        ts.run(arr)
    with pytest.raises(SampleError, match="state must be real numbers"):
        ts.run(rows, state=np.zeros(ts.n_state, dtype=complex))
    out, status, _ = ts.run(rows.astype(np.float32))                # real dtypes are converted
    assert np.isfinite(out).all()


@pytest.mark.slow       # runs a compiled extension (the fast lane has no build)
def test_run_refuses_a_masked_array_with_masked_samples(ts):
    rows = np.ma.masked_array(np.tile([20.0, 0.01], (10, 1)), mask=False)
    out, _, _ = ts.run(rows)                                         # nothing masked: run as given
    rows[3, 1] = np.ma.masked
    with pytest.raises(SampleError, match="masked array with 1 masked entries"):
        ts.run(rows)
    with pytest.raises(SampleError, match="state is a masked array"):
        state = np.ma.masked_array(np.zeros(ts.n_state), mask=[True] + [False] * (ts.n_state - 1))
        ts.run(rows.filled(0.0), state=state)


@pytest.mark.slow       # runs a compiled extension (the fast lane has no build)
def test_an_output_overlapping_the_inputs_is_refused(ts):
    buf = np.zeros(ts.n_input + ts.n_output)
    buf[:ts.n_input] = [20.0, 0.01]
    inputs, out = buf[:ts.n_input], buf[1:1 + ts.n_output]          # out starts inside the inputs
    state = ts.initial_state()
    with pytest.raises(ValueError, match="inputs and out overlap in memory"):
        ts.step(state, inputs, out)
    big = np.zeros(ts.n_state + ts.n_input)
    with pytest.raises(ValueError, match="state and inputs overlap"):
        ts.step(big[:ts.n_state], big[ts.n_state - 1:ts.n_state - 1 + ts.n_input], np.empty(ts.n_output))
    n = 50
    block = np.zeros(n * (ts.n_input + ts.n_output))
    rows, outs = block[:n * ts.n_input].reshape(n, ts.n_input), block[n:n + n * ts.n_output].reshape(n, ts.n_output)
    with pytest.raises(ValueError, match="inputs and outputs overlap"):
        ts.module.run(ts.initial_state(), rows, outs, np.empty(n, np.int32), n)
    good = np.empty(ts.n_output)                                     # separate arrays still work
    ts.step(state, buf[:ts.n_input].copy(), good)
    assert np.isfinite(good).all()


@pytest.mark.slow       # runs a compiled extension (the fast lane has no build)
def test_one_state_in_two_threads_is_refused_and_separate_states_run_together(ts):
    n = 1_000_000
    rows = np.tile([20.0, 0.01], (n, 1))
    shared = ts.initial_state()
    outcomes, busy = {}, threading.Event()

    def long_run():
        busy.set()
        outcomes["first"] = ts.module.run(shared, rows, np.empty((n, ts.n_output)), np.empty(n, np.int32), n)

    first = threading.Thread(target=long_run)
    first.start()
    busy.wait()
    refused = 0
    while first.is_alive():
        try:
            ts.module.run(shared, rows[:10], np.empty((10, ts.n_output)), np.empty(10, np.int32), 10)
        except RuntimeError as exc:
            assert "state is in use" in str(exc)
            refused += 1
    first.join()
    assert refused > 0, "the second thread never met the first one's run"
    # separate states: two threads at once give what one thread gives
    ref, _, _ = ts.run(rows[:200_000])
    results = [None, None]

    def own(k):
        results[k] = ts.run(rows[:200_000])[0]

    threads = [threading.Thread(target=own, args=(k,)) for k in range(2)]
    [t.start() for t in threads]
    [t.join() for t in threads]
    assert all(np.array_equal(r, ref) for r in results)


def test_the_description_leaves_out_the_starters_commands_and_notes(tmp_path):
    """`uiogen new --from-model` heads its file with commands, the trial's outcome and notes: hints
    for the user, not the description the generated C's header and the FMU carry."""
    path = tmp_path / "mine.toml"
    path.write_text("# mine: algebraic_uio for my rig.\n"
                    "# next: uiogen design THIS_FILE --update && uiogen generate THIS_FILE\n"
                    "# trial design by uiogen analyze (gain 1): certified\n"
                    "# note: the unknown input enters with relative degree 1\n"
                    "#   uiogen build mine.toml\n" + OBSERVER_FILE)
    doc = observers.get(str(path)).doc
    assert doc.startswith("mine: algebraic_uio for my rig. Example 1 of Ichalal"), doc
    assert not any(w in doc for w in ("next:", "trial design", "note:", "uiogen ")), doc


@pytest.mark.slow       # builds an extension
def test_an_observer_named_like_a_standard_module_leaves_it_alone(tmp_path):
    """An observer called socket compiles to _socket: loading it must not replace the standard
    library's _socket in sys.modules (import socket, ssl failed after load)."""
    project = tmp_path / "p"
    for args in (("new", str(project), "--family", "linf_uio", "--name", "socket"),
                 ("generate", str(project / "socket.toml")), ("build", str(project / "socket.toml"))):
        proc = _cli(*args)
        assert proc.returncode == 0, proc.stderr[-2000:]
    probe = ("import sys\nimport python_bindings as pb\nobs = pb.load(sys.argv[1])\n"
             "import socket, ssl\nassert socket.socket and ssl.SSLContext\n"
             "assert 'lib-dynload' in getattr(sys.modules['_socket'], '__file__', 'lib-dynload') "
             "and hasattr(sys.modules['_socket'], 'socket'), sys.modules['_socket']\n"
             "x = obs.initial_state()\nprint('ok', obs.name)\n")
    out = subprocess.run([sys.executable, "-c", probe, str(project / "socket.toml")], capture_output=True, text=True,
                         cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert out.returncode == 0 and out.stdout.strip() == "ok socket", out.stderr[-2000:]


# --- signal names: one rule at the model's import (codegen.model.names) --------------------------------------

@pytest.mark.parametrize("bad", ["NAN", "int", "errno", "INFINITY", "M_PI", "EOF", "v y", "\N{ROCKET}", "class", "x_",
                                 "EPERM", "Py_None", "casadi_real", "linux", "typeof", "M_PIl", "MAXFLOAT"])
def test_a_signal_name_that_cannot_be_a_c_field_is_one_line_at_the_first_verb(tmp_path, bad):
    """A state renamed (the symbol's name only): refused at design, before any C is written."""
    proc = _cli("new", str(tmp_path / "p"), "--family", "linf_uio", "--name", "obs1")
    assert proc.returncode == 0, proc.stderr
    model = tmp_path / "p" / "model.py"
    text = model.read_text()
    assert 'sp.symbols("beta r delta delta_dot")' in text
    model.write_text(text.replace('sp.symbols("beta r delta delta_dot")',
                                  f'(sp.Symbol({bad!r}), *sp.symbols("r delta delta_dot"))'))
    err = _one_line(_cli("design", str(tmp_path / "p" / "obs1.toml")))
    assert "ModelDefinitionError" in err and f"the state {bad!r}" in err and str(model) in err, err
    proc = _cli("generate", str(tmp_path / "p" / "obs1.toml"))     # the failure, named, in the summary line
    err = _one_line(proc)
    assert "ModelDefinitionError" in err and f"the state {bad!r}" in proc.stdout + proc.stderr
    assert not list((tmp_path / "p").rglob("*.c")) and not list((tmp_path / "p").rglob("*_design.json"))
